#!/usr/bin/env python3
"""Identification figures of a winding-from-resistance estimate against the plant's truth.

The figures of issue 34's identification goals (docs/resistance-identification.md, "TMP
identification scenarios"), computed from one estimate CSV and the scenario's truth CSV
(`pumptherm plant`'s `<pump>.truth.csv`, column `winding_resistance_degC`, one row a second):

  window     from the end of the run-up (the truth's first row with drive_state 2, steady at
             speed) plus --settle-s (default 0) to the truth's last row; every truth row in it
             is one evaluation point, compared with the estimate's latest row at or before it
             (sample and hold; none yet = nothing to compare).
  dT %       Han 2019 eq. 25: the largest |estimate - truth| over the window's points at which
             the estimate is a number (the DFRLS's held values included: the paper's method
             always gives one), divided by the mean true winding temperature over the window.
  max_published_error_K
             the largest |estimate - truth| over the points at which the reading is published.
  published  the share of the window's points at which the reading is published.

Published: in `pumptherm identify --log` output (the paper's DFRLS: columns time_s,
winding_resistance_degC, status as a code), status 2 (`tracking`); in the daemon's CSV
(`pumpthermd -r --csv-dir`) and in `pumptherm identify --config ... --pump ... --log` (the fused
estimator), a finite winding_resistance_degC (the daemon writes nan while it is not published;
docs/daemon.md, "Names"). Standard library only.

Figures of one file:
  tests/bench/ident_figures.py --truth out/tmp.truth.csv dfrls=out/dfrls.csv daemon=out/est/tmp.csv
The whole benchmark (both scenarios, the DFRLS, the daemon and the fused identify; a few minutes,
about 150 MB of recordings a scenario; not in CI):
  tests/bench/ident_figures.py --build build --out /tmp/ident
"""
import argparse
import bisect
import csv
import json
import math
import os
import subprocess
import sys

# The truth's winding under its current name and the names older plant versions wrote.
TRUTH_NAMES = ("winding_resistance_degC", "winding_resistance_C", "winding_res_C")
ESTIMATE_NAMES = ("winding_resistance_degC", "winding_resistance_C", "winding_res_degC",
                  "winding_res_C")
TRACKING = 2  # the identifier's status code for `tracking` (pumptherm identify --help)
STATUS_WORDS = {"initialising": 0, "converging": 1, "tracking": 2, "not_identifiable": 3,
                "implausible": 4, "invalid_input": 5, "held": 6}


def number(cell):
    try:
        return float(cell)
    except ValueError:
        return math.nan


def column(header, names, path):
    for n in names:
        if n in header:
            return header.index(n)
    raise SystemExit(f"{path}: no column {' or '.join(names)} (header: {','.join(header)})")


def read_truth(path):
    """(time_s, winding_degC, drive_state) lists of the truth CSV."""
    with open(path, newline="") as f:
        rows = csv.reader(f)
        header = next(rows)
        it, iw = column(header, ("time_s",), path), column(header, TRUTH_NAMES, path)
        idr = column(header, ("drive_state",), path)
        t, w, d = [], [], []
        for r in rows:
            t.append(float(r[it]))
            w.append(float(r[iw]))
            d.append(float(r[idr]))
    return t, w, d


def read_estimate(path):
    """(time_s, winding_degC, published) lists; the kind of file is told by its header."""
    with open(path, newline="") as f:
        rows = csv.reader(f)
        header = next(rows)
        it, iw = column(header, ("time_s",), path), column(header, ESTIMATE_NAMES, path)
        # `status` is the DFRLS output's; the daemon's CSV has a winding only while it is published.
        ist = header.index("status") if "status" in header else None
        t, w, pub = [], [], []
        for r in rows:
            t.append(float(r[it]))
            v = number(r[iw])
            w.append(v)
            if ist is None:
                pub.append(math.isfinite(v))
            else:
                code = STATUS_WORDS.get(r[ist], number(r[ist]))
                pub.append(code == TRACKING and math.isfinite(v))
    return t, w, pub


def figures(truth, estimate, settle_s=0.0):
    """The identification figures (a dict) of `estimate` against `truth` (see the docstring)."""
    tt, tw, drive = truth
    et, ew, epub = estimate
    steady = next((i for i, d in enumerate(drive) if d == 2), None)
    if steady is None:
        raise SystemExit("the truth never reaches drive_state 2 (steady at speed): no run-up end")
    start_s = tt[steady] + settle_s
    points = [i for i in range(len(tt)) if tt[i] >= start_s]
    if not points:
        raise SystemExit(f"no truth row from {start_s} s on")
    mean_true = sum(tw[i] for i in points) / len(points)
    worst = worst_published = 0.0
    published = compared = 0
    for i in points:
        k = bisect.bisect_right(et, tt[i] + 1e-9) - 1
        if k < 0 or not math.isfinite(ew[k]):
            continue
        err = abs(ew[k] - tw[i])
        compared += 1
        worst = max(worst, err)
        if epub[k]:
            published += 1
            worst_published = max(worst_published, err)
    return {
        "window_s": [start_s, tt[points[-1]]],
        "points": len(points),
        "mean_true_degC": mean_true,
        "dT_pct": 100.0 * worst / mean_true if compared else math.nan,
        "compared_points": compared,
        "max_published_error_K": worst_published if published else math.nan,
        "published_pct": 100.0 * published / len(points),
    }


def table(results):
    """Markdown rows: scenario, estimate, dT, largest published error, published share."""
    lines = ["| scenario | estimate | window s | dT % (eq. 25) | max error while published K "
             "| published % |", "| --- | --- | --- | --- | --- | --- |"]
    for (scenario, label), f in results:
        lines.append(f"| {scenario} | {label} | {f['window_s'][0]:.0f}-{f['window_s'][1]:.0f} "
                     f"| {f['dT_pct']:.2f} | {f['max_published_error_K']:.2f} "
                     f"| {f['published_pct']:.1f} |")
    return "\n".join(lines)


def run(cmd, **kw):
    print("+ " + " ".join(cmd), file=sys.stderr)
    subprocess.run(cmd, check=True, **kw)


def benchmark(a):
    """Both scenarios through the DFRLS, the daemon and the fused identify; returns results."""
    src = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    pumptherm = os.path.join(a.build, "tools/pumptherm")
    pumpthermd = os.path.join(a.build, "daemon/pumpthermd")
    config = os.path.join(src, "tests/bench/tmp_ident_pumpthermd.toml")
    results = []
    for scenario in a.scenarios:
        out = os.path.join(a.out, scenario)
        log = os.path.join(out, scenario + ".log")
        if not a.reuse:
            run([pumptherm, "plant", os.path.join(src, "tools/plant/scenarios", scenario + ".toml"),
                 "--out", out, "--quiet"])
            run([pumptherm, "identify", "--log", log, "--node-id", "1",
                 "-o", os.path.join(out, "dfrls.csv")])
            with open(os.path.join(out, "pumpthermd.txt"), "w") as err:
                run([pumpthermd, "--config", config, "-r", log, "--pace", "0",
                     "--csv-dir", os.path.join(out, "estimates")], stderr=err, stdout=err)
            with open(os.path.join(out, "identify-fused.txt"), "w") as err:
                run([pumptherm, "identify", "--config", config, "--pump", "tmp", "--log", log,
                     "-o", os.path.join(out, "fused.csv")], stderr=err)
        truth = read_truth(os.path.join(out, "tmp.truth.csv"))
        for label, path in (("DFRLS (identify --log)", "dfrls.csv"),
                            ("daemon (pumpthermd -r)", "estimates/tmp.csv"),
                            ("fused (identify --config)", "fused.csv")):
            f = figures(truth, read_estimate(os.path.join(out, path)), a.settle_s)
            results.append(((scenario, label), f))
    return results


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("estimates", nargs="*", metavar="LABEL=CSV",
                    help="estimate CSVs to judge against --truth")
    ap.add_argument("--truth", help="the scenario's truth CSV (with LABEL=CSV)")
    ap.add_argument("--settle-s", type=float, default=0.0,
                    help="the window starts this long after the run-up's end, s")
    ap.add_argument("--build", help="build directory: run the whole benchmark")
    ap.add_argument("--out", default="ident-figures", help="benchmark output directory")
    ap.add_argument("--scenarios", nargs="+", default=["tmp-ident-clean", "tmp-ident-disturbed"])
    ap.add_argument("--reuse", action="store_true", help="reuse the benchmark's files in --out")
    ap.add_argument("--json", help="write the figures here too")
    a = ap.parse_args()
    if a.build:
        results = benchmark(a)
    elif a.truth and a.estimates:
        truth = read_truth(a.truth)
        results = []
        for item in a.estimates:
            label, sep, path = item.partition("=")
            if not sep:
                ap.error(f"{item}: expected LABEL=CSV")
            results.append(((os.path.basename(a.truth), label),
                            figures(truth, read_estimate(path), a.settle_s)))
    else:
        ap.error("give --build (the benchmark) or --truth and LABEL=CSV")
    print(table(results))
    if a.json:
        with open(a.json, "w") as f:
            json.dump([{"scenario": s, "estimate": l, **f} for (s, l), f in results], f, indent=1)


if __name__ == "__main__":
    main()
