#!/usr/bin/env python3
"""Checks what the subscriber saw (subscriber.py's JSON lines) against the daemon's own CSV.

- NBIRTH: seq 0, bdSeq, Node Control/Rebirth; every NDEATH carries the bdSeq of a birth.
- DBIRTH per pump: every CSV column of the pump's is a metric of the same name (a node's
  `<node>_degC`, `<node>_sd_K` and the published fields), each with a unique alias.
- DDATA: applied by alias onto the birth's values, the pump's values after the step at time t
  equal the CSV's row at t, for every row: numbers within the CSV's rounding, "not available"
  (empty or nan) as is_null, a code whose CSV is a word the same word every time (a bijection
  over the run; alarm_level as docs/daemon.md numbers it: normal 0, warning 1, trip 2).
- seq: +1 per message of the edge node's session, mod 256.
Prints what it compared; exits 1 on the first kind of mismatch (up to 10 shown).
"""
import argparse
import csv
import json
import math
import sys
from collections import defaultdict

LEVEL = {"normal": 0, "warning": 1, "trip": 2}


def close(csv_text, v):
    """Whether value v, written as the CSV writes it, could be csv_text."""
    if csv_text == "" or csv_text == "nan":
        return v is None or v == "nan" or v == "inf"
    if v is None:
        return False
    if v in ("inf", "-inf"):
        return csv_text in ("inf", "-inf") and csv_text == v
    x = float(csv_text)
    mantissa, _, exponent = csv_text.lower().partition("e")
    decimals = len(mantissa.split(".")[1]) if "." in mantissa else 0
    # Half the last printed digit: fixed (%.Nf) or general (%.Ng, maybe with an exponent).
    half = 0.5 * 10 ** (int(exponent or 0) - decimals)
    return abs(x - v) <= half * 1.000001 + 1e-15


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--messages", required=True)
    ap.add_argument("--csv-dir", required=True)
    ap.add_argument("--group", required=True)
    ap.add_argument("--edge-node", required=True)
    ap.add_argument("--pumps", nargs="+", required=True)
    ap.add_argument("--origin-s", type=float, required=True, help="the CSV's time_s origin")
    a = ap.parse_args()
    msgs = [json.loads(line) for line in open(a.messages)]
    errors = []

    def err(text):
        errors.append(text)

    base = f"spBv1.0/{a.group}/"
    births = [m for m in msgs if m["topic"] == f"{base}NBIRTH/{a.edge_node}"]
    deaths = [m for m in msgs if m["topic"] == f"{base}NDEATH/{a.edge_node}"]
    if not births:
        err("no NBIRTH")
    bd_seqs = set()
    for b in births:
        names = {m["name"]: m for m in b["metrics"]}
        if b["seq"] != 0:
            err(f"NBIRTH seq {b['seq']}, not 0")
        if "bdSeq" not in names or "Node Control/Rebirth" not in names:
            err(f"NBIRTH without bdSeq or Node Control/Rebirth: {sorted(names)}")
        else:
            bd_seqs.add(names["bdSeq"]["value"])
            if names["Node Control/Rebirth"]["value"] is not False:
                err("NBIRTH: Node Control/Rebirth is not false")
    if not deaths:
        err("no NDEATH")
    for d in deaths:
        bd = [m["value"] for m in d["metrics"] if m["name"] == "bdSeq"]
        if not bd or bd[0] not in bd_seqs:
            err(f"NDEATH bdSeq {bd} is none of the births' {sorted(bd_seqs)}")

    # seq over the edge node's messages (NDEATH has none), restarting at each NBIRTH.
    expect = None
    for m in msgs:
        if not m["topic"].startswith(base) or m["topic"].split("/")[3] != a.edge_node:
            continue
        kind = m["topic"].split("/")[2]
        if kind == "NDEATH":
            continue
        if kind == "NBIRTH":
            expect = 0
        if expect is not None and m["seq"] != expect:
            err(f"{m['topic']}: seq {m['seq']}, expected {expect}")
        expect = ((m["seq"] if m["seq"] is not None else 0) + 1) % 256

    words = defaultdict(dict)  # column -> code -> word
    compared_rows = 0
    compared_cells = 0
    for pump in a.pumps:
        rows = list(csv.DictReader(open(f"{a.csv_dir}/{pump}.csv")))
        dbirths = [m for m in msgs if m["topic"] == f"{base}DBIRTH/{a.edge_node}/{pump}"]
        if not dbirths:
            err(f"{pump}: no DBIRTH")
            continue
        birth = dbirths[0]
        by_alias = {}
        values = {}
        for m in birth["metrics"]:
            if m["alias"] in by_alias:
                err(f"{pump}: alias {m['alias']} twice")
            by_alias[m["alias"]] = m["name"]
            values[m["name"]] = None if m["is_null"] else m["value"]
        columns = [c for c in rows[0].keys() if c != "time_s"] if rows else []
        missing = [c for c in columns if c not in values]
        shared = [c for c in columns if c in values]
        print(f"{pump}: {len(birth['metrics'])} metrics in DBIRTH; {len(shared)} of "
              f"{len(columns)} CSV columns by the same name"
              + (f"; not compared (named otherwise in the CSV): {missing}" if missing else ""))
        if len(shared) < len(columns) - 4:
            err(f"{pump}: only {len(shared)} of {len(columns)} CSV columns are metrics")
        # A code (UInt32, 7) is a word in the CSV.
        types = {m["name"]: m["datatype"] for m in birth["metrics"]}
        word_columns = {c for c in shared if types[c] == 7}
        data = defaultdict(list)
        for m in msgs:
            if m["topic"] == f"{base}DDATA/{a.edge_node}/{pump}":
                data[m["timestamp"]].append(m)
        for row in rows:
            t_ms = round((float(row["time_s"]) + a.origin_s) * 1000.0)
            # The CSV's time has 3 decimals: the DDATA within 1 ms of it.
            step = data.pop(t_ms, []) or data.pop(t_ms - 1, []) or data.pop(t_ms + 1, [])
            for m in step:
                for metric in m["metrics"]:
                    name = by_alias.get(metric["alias"])
                    if name is None:
                        err(f"{pump}: DDATA alias {metric['alias']} not in the DBIRTH")
                        continue
                    values[name] = None if metric["is_null"] else metric["value"]
            compared_rows += 1
            for c in shared:
                text, v = row[c], values[c]
                compared_cells += 1
                if c in word_columns:
                    # A word: the code behind it must map to one word, and one word to a code.
                    if c == "alarm_level" and LEVEL.get(text) != v:
                        err(f"{pump} t={row['time_s']} alarm_level: CSV {text}, MQTT {v}")
                    seen = words[c].setdefault(v, text)
                    if seen != text:
                        err(f"{pump} t={row['time_s']} {c}: code {v} is '{seen}' and '{text}'")
                elif not close(text, v):
                    err(f"{pump} t={row['time_s']} {c}: CSV '{text}', MQTT {v}")
        if data:
            err(f"{pump}: {len(data)} DDATA at times with no CSV row, e.g. {sorted(data)[:3]}")
    for c, codes in words.items():
        known = {k: w for k, w in codes.items() if k is not None}
        if len(set(known.values())) != len(known):
            err(f"{c}: two codes for one word: {codes}")
    print(f"compared {compared_rows} CSV rows, {compared_cells} cells; {len(births)} NBIRTH, "
          f"{len(deaths)} NDEATH, {len(msgs)} messages")
    if errors:
        cols = sorted({e.split(" ")[2].rstrip(":") for e in errors if " t=" in e})
        print(f"{len(errors)} mismatches (columns: {cols}):", file=sys.stderr)
        for e in errors[:10]:
            print("  " + e, file=sys.stderr)
        return 1
    return 0


def _numeric(text):
    try:
        float(text)
        return True
    except ValueError:
        return False


if __name__ == "__main__":
    sys.exit(main())
