#!/usr/bin/env python3
"""Checks a run across a broker restart (broker_test.sh, part 3) against the daemon's own CSV.

- Every alarm transition of the CSV (a row whose alarm_level, alarm_reason, alarm_node or
  alarm_active_reasons differs from the row before) arrived as a DDATA of its pump at the row's
  time, in the order of the CSV; each metric that message carries equals the CSV row (numbers
  within the CSV's rounding, alarm_level as docs/daemon.md numbers it, a code the same word
  each time).
- The broker went away: there are at least two NBIRTHs, and a DBIRTH of each pump after the
  last one. bdSeq counts CONNECT packets (Sparkplug 3.0.0; docs/mqtt.md, "Payloads"): the first
  NBIRTH carries 0, and the last 1, since the attempts while the broker was down sent no
  CONNECT (connection refused); a rebirth repeats its session's bdSeq.
- The data steps that did not arrive are counted by the daemon: --dropped (its summary's
  "N dropped") is at least 1, and the steps missing beyond it (QoS 0 messages written to a
  connection that was already gone: libmosquitto took them, the broker never read them) are at
  most --max-lost.
With --no-restart (a run without a broker outage, the slow-consumer test): no NBIRTH, bdSeq or
"dropped at least 1" checks; the alarm transitions and the missing steps as above.
Prints the figures; exits 1 on a mismatch.
"""
import argparse
import csv
import json
import sys
from collections import defaultdict

from check_messages import LEVEL, close

ALARM = ("alarm_level", "alarm_reason", "alarm_node", "alarm_active_reasons")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--messages", required=True)
    ap.add_argument("--csv-dir", required=True)
    ap.add_argument("--group", required=True)
    ap.add_argument("--edge-node", required=True)
    ap.add_argument("--pumps", nargs="+", required=True)
    ap.add_argument("--origin-s", type=float, required=True)
    ap.add_argument("--dropped", type=int, required=True, help="the daemon's 'N dropped'")
    ap.add_argument("--max-lost", type=int, required=True)
    ap.add_argument("--no-restart", action="store_true")
    a = ap.parse_args()
    msgs = [json.loads(line) for line in open(a.messages)]
    base = f"spBv1.0/{a.group}/"
    errors = []
    nbirths = [i for i, m in enumerate(msgs) if m["topic"] == f"{base}NBIRTH/{a.edge_node}"]
    if len(nbirths) < 2 and not a.no_restart:
        errors.append(f"{len(nbirths)} NBIRTH: the daemon did not connect again")
    bd_seqs = [[x["value"] for x in msgs[i]["metrics"] if x["name"] == "bdSeq"][0] for i in nbirths]
    if bd_seqs and not a.no_restart and (bd_seqs[0] != 0 or bd_seqs[-1] != 1 or bd_seqs != sorted(bd_seqs)):
        errors.append(f"NBIRTH bdSeq {bd_seqs}: want 0 first, 1 last (one CONNECT after the outage)")
    words = defaultdict(dict)
    steps = received = transitions = 0
    for pump in a.pumps:
        rows = list(csv.DictReader(open(f"{a.csv_dir}/{pump}.csv")))
        steps += len(rows)
        births = [i for i, m in enumerate(msgs) if m["topic"] == f"{base}DBIRTH/{a.edge_node}/{pump}"]
        if not births or (nbirths and births[-1] < nbirths[-1]):
            errors.append(f"{pump}: no DBIRTH after the last NBIRTH")
            continue
        by_alias = {x["alias"]: x["name"] for x in msgs[births[0]]["metrics"]}
        types = {x["name"]: x["datatype"] for x in msgs[births[0]]["metrics"]}
        data = {}  # time (ms) -> metrics of the DDATA, in arrival order
        order = []
        for m in msgs:
            if m["topic"] == f"{base}DDATA/{a.edge_node}/{pump}":
                data[m["timestamp"]] = m["metrics"]
                order.append(m["timestamp"])
        received += len(data)
        seen_at = []
        prev = None
        for row in rows:
            key = tuple(row[c] for c in ALARM)
            if prev is not None and key != prev:
                transitions += 1
                t_ms = round((float(row["time_s"]) + a.origin_s) * 1000.0)
                t = next((x for x in (t_ms, t_ms - 1, t_ms + 1) if x in data), None)
                if t is None:
                    errors.append(f"{pump} t={row['time_s']}: the alarm transition {key} did not arrive")
                else:
                    seen_at.append(order.index(t))
                    print(f"{pump} t={row['time_s']}: {'/'.join(key)} arrived")
                    for x in data[t]:
                        name = by_alias.get(x["alias"])
                        if name not in row:
                            continue
                        v = None if x["is_null"] else x["value"]
                        if types[name] == 7:
                            if name == "alarm_level" and LEVEL.get(row[name]) != v:
                                errors.append(f"{pump} t={row['time_s']} alarm_level: CSV {row[name]}, MQTT {v}")
                            if words[name].setdefault(v, row[name]) != row[name]:
                                errors.append(f"{pump} t={row['time_s']} {name}: code {v} is two words")
                        elif not close(row[name], v):
                            errors.append(f"{pump} t={row['time_s']} {name}: CSV '{row[name]}', MQTT {v}")
            prev = key
        if seen_at != sorted(seen_at):
            errors.append(f"{pump}: alarm transitions out of order")
    lost = steps - received - a.dropped
    print(f"{len(nbirths)} NBIRTH (bdSeq {bd_seqs}); {transitions} alarm transitions in the CSV; {steps} steps, "
          f"{received} DDATA received, {a.dropped} dropped (counted), {lost} missing beyond them")
    if a.dropped < 1 and not a.no_restart:
        errors.append("nothing dropped: the outage did not fill the queue")
    if transitions < 1:
        errors.append("no alarm transition in the CSV: the test proves nothing")
    if lost > a.max_lost:
        errors.append(f"{lost} steps missing beyond the counted drops (at most {a.max_lost})")
    for e in errors[:10]:
        print("  " + e, file=sys.stderr)
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main())
