#!/usr/bin/env python3
"""The published identification against the plant's truth, per published status.

For each pump CSV in OUT/estimates (pumpthermd -r --csv-dir) and its truth OUT/<pump>.truth.csv
(pumptherm plant --out), after --after-s: the rows of each `ident_status`, how many carry Rs and
the flux, their largest errors and how many lie inside +-2 sd. A table a terminal shows well.

  tests/bench/ident_coverage.py /tmp/fm [--after-s 300]
"""
import argparse
import csv
import glob
import math
import os
import sys


def number(text):
    try:
        return float(text)
    except (TypeError, ValueError):
        return math.nan


def pump_rows(estimate_csv, truth_csv, after_s):
    """Yields (status, Rs, Rs sd, true Rs, flux, flux sd, true flux) per row after after_s."""
    with open(truth_csv, newline='') as f:
        truth = {round(number(r['time_s'])): r for r in csv.DictReader(f)}
    with open(estimate_csv, newline='') as f:
        for line, r in enumerate(csv.DictReader(f), start=2):
            t = round(number(r.get('time_s')))
            if not t >= after_s or t not in truth:
                continue
            try:
                yield (r['ident_status'], number(r['resistance_ohm']), number(r['resistance_sd_ohm']),
                       number(truth[t]['resistance_ohm']), number(r['flux_Wb']),
                       number(r['flux_sd_Wb']), number(truth[t]['flux_Wb']))
            except KeyError as e:
                sys.exit(f'{estimate_csv}:{line}: no column {e} (a CSV of pumpthermd -r, and its '
                         'truth from pumptherm plant --out?)')


def summarise(rows):
    """status -> [rows, with Rs, Rs covered, Rs max |err| ohm, with flux, flux covered, flux max rel]"""
    table = {}
    for status, r, r_sd, r_true, psi, psi_sd, psi_true in rows:
        s = table.setdefault(status, [0, 0, 0, 0.0, 0, 0, 0.0])
        s[0] += 1
        if math.isfinite(r):
            e = abs(r - r_true)
            s[1] += 1
            s[2] += e <= 2 * r_sd
            s[3] = max(s[3], e)
        if math.isfinite(psi):
            e = abs(psi - psi_true)
            s[4] += 1
            s[5] += e <= 2 * psi_sd
            s[6] = max(s[6], e / abs(psi_true))
    return table


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('out', help='directory with estimates/<pump>.csv and <pump>.truth.csv')
    ap.add_argument('--after-s', type=float, default=300.0, help='judge rows from this time on')
    a = ap.parse_args()
    csvs = sorted(glob.glob(os.path.join(a.out, 'estimates', '*.csv')))
    if not csvs:
        sys.exit(f'{a.out}/estimates: no pump CSV')
    head = ('pump', 'status', 'rows', 'Rs rows', 'Rs in 2sd', 'Rs max err ohm',
            'flux rows', 'flux in 2sd', 'flux max err %')
    lines = []
    for est in csvs:
        pump = os.path.basename(est)[:-4]
        truth = os.path.join(a.out, pump + '.truth.csv')
        if not os.path.exists(truth):
            sys.exit(f'{truth}: no truth for {est}')
        for status, s in summarise(pump_rows(est, truth, a.after_s)).items():
            lines.append((pump, status, str(s[0]), str(s[1]), str(s[2]),
                          f'{s[3]:.4f}' if s[1] else '-', str(s[4]), str(s[5]),
                          f'{100 * s[6]:.2f}' if s[4] else '-'))
    widths = [max(len(x[i]) for x in [head] + lines) for i in range(len(head))]
    for row in [head] + lines:
        print('  '.join(c.ljust(w) if i < 2 else c.rjust(w) for i, (c, w) in enumerate(zip(row, widths))))


if __name__ == '__main__':
    main()
