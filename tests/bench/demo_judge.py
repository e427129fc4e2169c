#!/usr/bin/env python3
"""Judges the demo, node by node, against the plant simulator's truth.

Runs `pumptherm plant demo` (unless --reuse), the gateway offline on its recording
(`pumpthermd -r`, no pacing) with tools/demo/pumpthermd-demo.toml, and reports per pump:
  - per estimated node, after --skip-s (300 s): max |estimate - truth| and the share of steps in
    which the truth lies within estimate +- 2 sd (coverage);
  - the same for the winding temperature from resistance (against the truth's winding_resistance_degC)
    and, when the CSV has it, the magnet temperature from the flux (against the truth of the
    magnet node, by its sd), and for the published identification, Rs in milliohm and psi_f in
    microweber (resistance_mohm, flux_uWb; its errors are in those units, not K);
  - the first warning and trip against the truth's first crossings (summary.json).
Prints a table and writes judge.json into the output directory. Standard library only.
With --check it exits 1 when a goal of the demo is missed (docs/virtual-sensor.md, "The demo
judged node by node"): a node more than --max-error-K off or covered less than --min-coverage
of the time, the winding from resistance published less than 80 % of the time or covered less
than --min-coverage of it, Rs or psi_f covered less than --min-coverage where published, or an alarm on a pump whose truth never crosses the level, or a warning or trip
later than 30 s after (or earlier than 120 s before) the true crossing.

Example:
  tests/bench/demo_judge.py --build build --out /tmp/demo-judge
  tests/bench/demo_judge.py --build build --out /tmp/demo-judge --check   # as CTest's demo_judge
"""
import argparse
import bisect
import csv
import json
import math
import os
import subprocess
import sys


# Codes the CSV files write as words (docs/daemon.md, "Names"): word -> number.
LEVELS = {"normal": 0.0, "warning": 1.0, "trip": 2.0}
# Columns of files written before one name per quantity: old -> current.
RENAMED = {"winding_res_degC": "winding_resistance_degC", "frame_measured_degC": "frame_sensor_degC"}


def current_name(name):
    """A column's current name: a temperature under `_degC` (old files wrote `_C`)."""
    if name.endswith("_C"):
        name = name[:-2] + "_degC"
    return RENAMED.get(name, name)


def read_csv(path):
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    header, body = [current_name(n) for n in rows[0]], rows[1:]
    cols = {name: [] for name in header}
    for r in body:
        for name, v in zip(header, r):
            try:
                cols[name].append(float(v))
            except ValueError:
                cols[name].append(LEVELS.get(v, math.nan) if name == "alarm_level" else math.nan)
    return cols


def interp(ts, vs, t):
    """Linear interpolation of the series (ts ascending) at t; NaN outside."""
    i = bisect.bisect_left(ts, t)
    if i < len(ts) and ts[i] == t:
        return vs[i]
    if i == 0 or i >= len(ts):
        return math.nan
    a = (t - ts[i - 1]) / (ts[i] - ts[i - 1])
    return vs[i - 1] + a * (vs[i] - vs[i - 1])


def judge_series(est_t, est_v, est_sd, truth_t, truth_v, skip_s):
    """Max |error|, coverage (truth within +-2 sd), the sample count and the share of rows with
    a value (available) after skip_s."""
    max_err, inside, n, rows = 0.0, 0, 0, 0
    for t, v, sd in zip(est_t, est_v, est_sd):
        if t < skip_s:
            continue
        rows += 1
        if not math.isfinite(v):
            continue
        truth = interp(truth_t, truth_v, t)
        if not math.isfinite(truth):
            continue
        err = abs(v - truth)
        max_err = max(max_err, err)
        n += 1
        if math.isfinite(sd) and err <= 2.0 * sd:
            inside += 1
    return {"max_abs_error_K": round(max_err, 2) if n else None,
            "coverage_2sd": round(inside / n, 3) if n else None, "samples": n,
            "available": round(n / rows, 3) if rows else None}


def first_at_or_above(ts, vs, level):
    for t, v in zip(ts, vs):
        if math.isfinite(v) and v >= level:
            return t
    return None


def run(cmd, **kw):
    print("+ " + " ".join(cmd), file=sys.stderr)
    subprocess.run(cmd, check=True, **kw)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--build", default="build", help="build directory with pumpthermd, pumptherm")
    ap.add_argument("--out", default="demo-judge", help="output directory")
    ap.add_argument("--scenario", default="demo", help="plant scenario (shipped name or path)")
    ap.add_argument("--config", default="tools/demo/pumpthermd-demo.toml", help="daemon configuration")
    ap.add_argument("--skip-s", type=float, default=300.0, help="judge from this time on, s")
    ap.add_argument("--magnet-node", default="rotor", help="truth node the magnet temperature is judged against")
    ap.add_argument("--reuse", action="store_true", help="reuse the recording and estimates in --out")
    ap.add_argument("--check", action="store_true", help="exit 1 when a goal is missed")
    ap.add_argument("--max-error-K", type=float, default=3.0, help="goal for every node's max |error|, K")
    ap.add_argument("--node-max-error-K", action="append", default=[], metavar="NODE=K",
                    help="a node's own bound instead of --max-error-K (a known shortfall: say why "
                         "where it is used); repeatable")
    ap.add_argument("--min-coverage", type=float, default=0.9, help="goal for every node's coverage")
    ap.add_argument("--no-resistance-goal", action="store_true",
                    help="no goal for the winding from resistance (pumps without the voltage rows)")
    ap.add_argument("--pump-setting", action="append", default=[], metavar="KEY=VALUE",
                    help="add this TOML line to every [[pump]] of --config (a copy in --out)")
    a = ap.parse_args()
    if a.pump_setting and not a.reuse:
        a.config = WithPumpSettings(a.config, a.pump_setting, a.out)

    est_dir = os.path.join(a.out, "estimates")
    if not a.reuse:
        os.makedirs(est_dir, exist_ok=True)
        run([os.path.join(a.build, "tools/pumptherm"), "plant", a.scenario, "--out", a.out],
            stdout=subprocess.DEVNULL)
        log = [f for f in os.listdir(a.out) if f.endswith(".log")][0]
        with open(os.path.join(a.out, log)) as f:
            origin = f.readline().split(")")[0].lstrip("(").split(".")[0]
        with open(os.path.join(a.out, "pumpthermd.txt"), "w") as o:
            run([os.path.join(a.build, "daemon/pumpthermd"), "--config", a.config, "-r",
                 os.path.join(a.out, log), "--pace", "0", "--csv-dir", est_dir,
                 "--csv-time-origin", origin], stdout=o, stderr=subprocess.STDOUT)

    with open(os.path.join(a.out, "summary.json")) as f:
        summary = json.load(f)
    report = {"skip_s": a.skip_s, "pumps": []}
    for p in summary["pumps"]:
        name = p["name"]
        truth = read_csv(os.path.join(a.out, name + ".truth.csv"))
        est = read_csv(os.path.join(est_dir, name + ".csv"))
        tt, et = truth["time_s"], est["time_s"]
        nodes = {}
        for col in est:
            if (col.endswith("_sd_K") and col[:-5] + "_degC" in est and col[:-5] + "_degC" in truth
                    and col != "winding_resistance_sd_K"):
                node = col[:-5]
                nodes[node] = judge_series(et, est[node + "_degC"], est[col], tt, truth[node + "_degC"],
                                           a.skip_s)
        extra = {}
        if "winding_resistance_degC" in est and "winding_resistance_degC" in truth:
            sd = est.get("winding_resistance_sd_K", [math.nan] * len(et))
            extra["winding_from_resistance"] = judge_series(et, est["winding_resistance_degC"], sd, tt,
                                                            truth["winding_resistance_degC"], a.skip_s)
        if "magnet_flux_degC" in est and a.magnet_node + "_degC" in truth:
            extra["magnet_from_flux"] = judge_series(et, est["magnet_flux_degC"], est["magnet_flux_sd_K"], tt,
                                                     truth[a.magnet_node + "_degC"], a.skip_s)
        # The published identification where it is published (the fused filter's; the DFRLS
        # identifier's status carries none): milliohm and microweber, so two decimals show it.
        for col, sd_col, scale, key in (("resistance_ohm", "resistance_sd_ohm", 1e3, "resistance_mohm"),
                                        ("flux_Wb", "flux_sd_Wb", 1e6, "flux_uWb")):
            if col in est and sd_col in est and col in truth:
                extra[key] = judge_series(et, [v * scale for v in est[col]], [v * scale for v in est[sd_col]],
                                          tt, [v * scale for v in truth[col]], a.skip_s)
        level = est.get("alarm_level", [])
        alarms = {"warning_s": first_at_or_above(et, level, 1.0), "trip_s": first_at_or_above(et, level, 2.0),
                  "true_warning_s": p.get("warning_crossed_s"), "true_trip_s": p.get("trip_crossed_s")}
        report["pumps"].append({"name": name, "nodes": nodes, "extra": extra, "alarms": alarms})

    print(f"after {a.skip_s:.0f} s: max |error| K / coverage of +-2 sd")
    for p in report["pumps"]:
        cells = [f"{k} {v['max_abs_error_K']} / {v['coverage_2sd']}" for k, v in p["nodes"].items()]
        cells += [f"{k} {v['max_abs_error_K']} / {v['coverage_2sd']} (available {v['available']})"
                  for k, v in p["extra"].items()]
        print(f"  {p['name']}: " + "; ".join(cells))
        al = p["alarms"]
        print(f"    warning {al['warning_s']} s (truth {al['true_warning_s']}), trip {al['trip_s']} s "
              f"(truth {al['true_trip_s']})")
    with open(os.path.join(a.out, "judge.json"), "w") as f:
        json.dump(report, f, indent=1)
    if a.check:
        bounds = {}
        for item in a.node_max_error_K:
            node, sep, value = item.partition("=")
            if not sep:
                ap.error(f"--node-max-error-K {item}: expected NODE=K")
            bounds[node] = float(value)
        missed = Missed(report, a.max_error_K, a.min_coverage, bounds, not a.no_resistance_goal)
        for m in missed:
            print("MISSED: " + m)
        return 1 if missed else 0
    return 0


def WithPumpSettings(config, settings, out):
    """A copy of `config` in `out` with each KEY=VALUE line added to every [[pump]] table."""
    for item in settings:
        if "=" not in item:
            sys.exit(f"--pump-setting {item}: expected KEY=VALUE")
    lines = []
    with open(config) as f:
        for line in f:
            lines.append(line)
            if line.strip() == "[[pump]]":
                lines += [item + "\n" for item in settings]
    os.makedirs(out, exist_ok=True)
    path = os.path.join(out, "pumpthermd.toml")
    with open(path, "w") as f:
        f.writelines(lines)
    return path


def Missed(report, max_error_K, min_coverage, node_max_error_K=None, resistance_goal=True):
    """The goals the report misses, one line each. node_max_error_K: {node: K} overrides;
    resistance_goal: the winding from resistance is published and honest."""
    out = []
    for p in report["pumps"]:
        for node, v in p["nodes"].items():
            bound = (node_max_error_K or {}).get(node, max_error_K)
            if v["max_abs_error_K"] is None or v["max_abs_error_K"] > bound:
                out.append(f"{p['name']} {node}: max |error| {v['max_abs_error_K']} K > {bound} K")
            if v["coverage_2sd"] is None or v["coverage_2sd"] < min_coverage:
                out.append(f"{p['name']} {node}: coverage {v['coverage_2sd']} < {min_coverage}")
        # The winding from resistance: published most of the time, and honest when it is.
        w = p["extra"].get("winding_from_resistance")
        if resistance_goal:
            if w is None or w["available"] is None or w["available"] < 0.8:
                out.append(f"{p['name']} winding from resistance: available {w and w['available']} < 0.8")
            elif w["coverage_2sd"] is None or w["coverage_2sd"] < min_coverage:
                out.append(f"{p['name']} winding from resistance: coverage {w['coverage_2sd']} < {min_coverage}")
        # Rs and psi_f as published: honest wherever they are published, how often is not a goal.
        for key in ("resistance_mohm", "flux_uWb"):
            v = p["extra"].get(key)
            if v and v["samples"] and v["coverage_2sd"] < min_coverage:
                out.append(f"{p['name']} {key}: coverage {v['coverage_2sd']} < {min_coverage} "
                           f"where published ({v['samples']} rows)")
        al = p["alarms"]
        for level in ("warning", "trip"):
            got, truth = al[level + "_s"], al["true_" + level + "_s"]
            if truth is None and got is not None:
                out.append(f"{p['name']}: {level} at {got} s, the truth never crosses")
            elif truth is not None and (got is None or not truth - 120.0 <= got <= truth + 30.0):
                out.append(f"{p['name']}: {level} at {got} s, outside [{truth} - 120, {truth} + 30] s")
    return out


if __name__ == "__main__":
    sys.exit(main())
