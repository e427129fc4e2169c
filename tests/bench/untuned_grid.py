#!/usr/bin/env python3
"""Faults of sizes, onsets and load shapes no bench was tuned on, judged against the truth.

Two grids, each written as plant scenarios of at most 16 pumps (a bus's node IDs) with a daemon
configuration beside them, recorded by `pumptherm plant`, run through `pumpthermd -r` and judged
by tests/bench/demo_judge.py:

  cooling  the demo's pump (tmp-generic, han2019-tmp, RTD lagging 30 s, R0 +2 %, flux -1.6 %,
           0.15 V dead time, 3 r/min ripple) at 21000 r/min under three load shapes (light steps,
           heavy steps, a ramp from 2 to 5 A without steps), its cooling edge's resistance x3, x8
           or x40 from 150, 600 or 1100 s; 35 min; levels 100 / 120 degC (27 pumps)
  iron     the same pump with its iron losses x0.7 to x2.0 of the model's, from the start, under
           the load steps of tests/bench/rotor_losses.toml at 21000 and 15000 r/min and heavy
           steps; 40 min; levels 70 / 80 degC, which these pumps reach (18 pumps)

Prints, per pump, the largest error and coverage of +-2 sd over the nodes (after 300 s), the
winding from resistance's availability, and the trip against the truth's crossing: how early
(negative: late), the truth and the estimate at the trip and the winding's sd there
(docs/virtual-sensor.md, "Cases no bench was tuned on"). A measurement, exit 0, unless --check:
then exit 1 when a trip comes after the truth's crossing or not at all, a node is covered less
than 90 % of the time or more than 3 K off, or a pump trips whose truth stays 6 K or more below
the trip level (CTest `untuned_grid_cooling` runs the cooling grid so; the iron grid misses).
Standard library only.

Example:
  tests/bench/untuned_grid.py --build build --out /tmp/untuned
  tests/bench/untuned_grid.py --build build --out /tmp/untuned-nv --pump-setting "voltage_reading = false"
  tests/bench/untuned_grid.py --build build --out /tmp/untuned --grid iron
  tests/bench/untuned_grid.py --build build --out /tmp/untuned --grid cooling --check
"""
import argparse
import concurrent.futures
import importlib.util
import json
import math
import os
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.dont_write_bytecode = True  # demo_judge.py is read from the source tree, which stays clean
_spec = importlib.util.spec_from_file_location("demo_judge", os.path.join(HERE, "demo_judge.py"))
judge = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(judge)

PLANT = """[defaults]
model = "tmp-generic"
motor = "han2019-tmp"
interface = "can0"
ambient_C = 22.0
frame_sensor = { node = "frame", lag_s = 30.0 }
motor_r0_scale = 1.02
motor_flux_scale = 0.984
drive = { magnet_node = "rotor", dead_time_V = 0.15, speed_ripple_rpm = 3.0 }
"""

# Load shapes: (speed r/min, [(duration s, iq A, iq at the end A)]); the ambient rises 1.6 K.
PROFILES = {
    "light": (21000, [(120, 3.0, 3.0), (300, 1.8, 2.0), (400, 2.6, 2.4), (500, 2.0, 2.2),
                      (1080, 2.8, 2.7)]),
    "heavy": (21000, [(120, 3.0, 3.0), (200, 3.8, 4.0), (500, 4.4, 4.6), (400, 3.6, 3.9),
                      (1180, 4.8, 4.7)]),
    "ramp": (21000, [(120, 3.0, 3.0), (2280, 2.0, 5.0)]),
    "gas": (21000, [(120, 3.0, 3.0), (200, 2.2, 2.4), (260, 3.4, 3.2), (180, 2.7, 2.9),
                    (320, 3.8, 3.6), (420, 2.5, 2.8), (500, 4.4, 4.2), (500, 1.6, 1.9)]),
    "slow": (15000, [(180, 2.5, 2.5), (300, 2.0, 2.3), (400, 3.0, 2.8), (620, 2.4, 2.6),
                     (900, 3.6, 3.3)]),
}


def profile_toml(name):
    speed, segments = PROFILES[name]
    lines, ambient = [f"[profile.{name}]", "segments = ["], 22.2
    for i, (duration, iq, iq_end) in enumerate(segments):
        speed_key = f"speed_rpm = {speed}, " if i == 0 else ""
        lines.append(f"  {{ duration_s = {duration}, {speed_key}iq_A = {iq}, "
                     f"iq_end_A = {iq_end}, ambient_C = {ambient:.1f} }},")
        ambient = min(ambient + 0.4, 23.8)
    lines.append("]")
    return "\n".join(lines) + "\n"


def cooling_pumps():
    return [(f"{prof}_x{factor}_at{onset}", prof,
             f'faults = [ {{ kind = "cooling_failure", start_s = {onset}, edge = "cooling", '
             f"factor = {factor}.0 }} ]")
            for prof in ("light", "heavy", "ramp") for factor in (3, 8, 40)
            for onset in (150, 600, 1100)]


def iron_pumps():
    return [(f"{prof}_iron{scale}", prof,
             f'effects = [ {{ name = "iron_loss_scale", values = [{scale}] }} ]')
            for prof in ("gas", "slow", "heavy") for scale in (0.7, 1.3, 1.5, 1.6, 1.8, 2.0)]


GRIDS = {
    # name: (pumps, duration s, warning degC, trip degC)
    "cooling": (cooling_pumps, 2100, 100.0, 120.0),
    "iron": (iron_pumps, 2400, 70.0, 80.0),
}


def write_group(out, name, pumps, duration_s, warning_C, trip_C, seed):
    """Writes one scenario of at most 16 pumps and its daemon configuration; returns both paths."""
    profiles = sorted({p[1] for p in pumps})
    scenario = [f'[scenario]\nname = "{name}"\ndescription = "untuned grid {name}"\n'
                f"duration_s = {duration_s}\nseed = {seed}\n",
                f'[levels]\nnode = "winding_resistance"\nwarning_C = {warning_C}\n'
                f"trip_C = {trip_C}\n", PLANT] + [profile_toml(p) for p in profiles]
    config = [f'[gateway]\nname = "{name}"\nheartbeat_period_s = 1.0\nthermal_period_s = 1.0\n',
              "[alarms]\nhysteresis_K = 2.0\nhold_s = 2.0\nstale_after_s = 2.0\n"
              "forecast_horizon_s = 300.0\n[alarms.levels]\n"
              f"winding = {{ warning_degC = {warning_C}, trip_degC = {trip_C} }}\n",
              '[[can]]\ninterface = "can0"\n']
    for node_id, (pump, profile, fault) in enumerate(pumps):
        scenario.append(f'[[pump]]\nname = "{pump}"\nnode_id = {node_id}\n'
                        f'profile = "{profile}"\n{fault}\n')
        config.append(f'[[pump]]\nname = "{pump}"\nnode_id = {node_id}\nmotor = "han2019-tmp"\n'
                      'thermal_model = "tmp-generic"\nmeasured_node = "frame"\n'
                      'magnet_node = "rotor"\nframe_sensor_lag_s = 30.0\n'
                      "disturbance_states = true\n")
    os.makedirs(out, exist_ok=True)
    paths = (os.path.join(out, f"{name}.toml"), os.path.join(out, f"{name}_pumpthermd.toml"))
    for path, text in zip(paths, ("\n".join(scenario), "\n".join(config))):
        with open(path, "w") as f:
            f.write(text)
    return paths


def run_group(args, name, scenario, config):
    cmd = [sys.executable, os.path.join(HERE, "demo_judge.py"), "--build", args.build,
           "--out", os.path.join(args.out, name), "--scenario", scenario, "--config", config]
    for s in args.pump_setting:
        cmd += ["--pump-setting", s]
    with open(os.path.join(args.out, f"{name}.txt"), "w") as log:
        subprocess.run(cmd, check=True, stdout=log, stderr=subprocess.STDOUT)
    return name


def trip_row(out, group, pump, alarms):
    """The judge's first trip and the truth's crossing (the plant's summary), with the truth, the
    estimate and its sd at the trip from the CSVs."""
    truth = judge.read_csv(os.path.join(out, group, f"{pump}.truth.csv"))
    tt, tw = truth["time_s"], truth["winding_resistance_degC"]
    t = alarms["trip_s"]
    row = {"true_trip_s": alarms["true_trip_s"], "trip_s": t, "truth_at_trip_degC": None,
           "estimate_at_trip_degC": None, "sd_at_trip_K": None, "truth_max_degC": max(tw)}
    if t is not None:
        est = judge.read_csv(os.path.join(out, group, "estimates", f"{pump}.csv"))
        i = est["time_s"].index(t)
        row.update(truth_at_trip_degC=judge.interp(tt, tw, t),
                   estimate_at_trip_degC=est["winding_degC"][i], sd_at_trip_K=est["winding_sd_K"][i])
    return row


def summarise(out, group):
    with open(os.path.join(out, group, "judge.json")) as f:
        report = json.load(f)
    rows = []
    for p in report["pumps"]:
        nodes = [v for v in p["nodes"].values() if v["max_abs_error_K"] is not None]
        wr = p["extra"].get("winding_from_resistance") or {}
        row = {"pump": p["name"], "max_error_K": max(v["max_abs_error_K"] for v in nodes),
               "min_coverage": min(v["coverage_2sd"] for v in nodes),
               "resistance_available": wr.get("available")}
        row.update(trip_row(out, group, p["name"], p["alarms"]))
        rows.append(row)
    return rows


def fmt(v, spec):
    return "-" if v is None or (isinstance(v, float) and math.isnan(v)) else format(v, spec)


def print_table(grid, rows):
    print(f"\n{grid}: after 300 s, every node's largest |error| and least coverage of +-2 sd;"
          " the trip against the truth's crossing (early > 0, late < 0)")
    print("| pump | max error K | coverage | winding from resistance | true trip s | trip s "
          "| early s | truth / estimate / sd at the trip |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for r in rows:
        early = (r["true_trip_s"] - r["trip_s"]
                 if r["true_trip_s"] is not None and r["trip_s"] is not None else None)
        if r["trip_s"] is None and r["true_trip_s"] is not None:
            early_text = "missed"
        elif r["trip_s"] is not None and r["true_trip_s"] is None:
            early_text = f"(truth max {r['truth_max_degC']:.1f})"
        else:
            early_text = fmt(early, ".0f")
        at_trip = ("-" if r["trip_s"] is None else
                   f"{r['truth_at_trip_degC']:.1f} / {r['estimate_at_trip_degC']:.1f} / "
                   f"{r['sd_at_trip_K']:.2f}")
        print(f"| {r['pump']} | {r['max_error_K']:.2f} | {100 * r['min_coverage']:.0f} % "
              f"| {fmt(r['resistance_available'], '.0%')} | {fmt(r['true_trip_s'], '.0f')} "
              f"| {fmt(r['trip_s'], '.0f')} | {early_text} | {at_trip} |")


def missed(grid, rows):
    """The --check goals each row misses, one line each."""
    trip_C = GRIDS[grid][3]
    out = []
    for r in rows:
        if r["max_error_K"] > 3.0 or r["min_coverage"] < 0.9:
            out.append(f"{r['pump']}: a node {r['max_error_K']} K off, covered "
                       f"{r['min_coverage']:.0%} at least (goals 3 K, 90 %)")
        if r["true_trip_s"] is not None and (r["trip_s"] is None or r["trip_s"] > r["true_trip_s"]):
            out.append(f"{r['pump']}: trip at {r['trip_s']} s, after the truth's crossing at "
                       f"{r['true_trip_s']:.1f} s")
        if r["trip_s"] is not None and r["truth_max_degC"] < trip_C - 6.0:
            out.append(f"{r['pump']}: trip at {r['trip_s']:.0f} s, the truth never above "
                       f"{r['truth_max_degC']:.1f} degC")
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--build", default="build", help="build directory with pumpthermd, pumptherm")
    ap.add_argument("--out", default="untuned-grid", help="output directory")
    ap.add_argument("--grid", action="append", choices=sorted(GRIDS), help="default: both")
    ap.add_argument("--pump-setting", action="append", default=[], metavar="KEY=VALUE",
                    help="added to every [[pump]] of the configurations (as demo_judge.py)")
    ap.add_argument("--check", action="store_true", help="exit 1 when a goal is missed (above)")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="groups at a time")
    args = ap.parse_args()
    grids = args.grid or sorted(GRIDS)
    groups = []  # (grid, group name, scenario, config)
    for grid in grids:
        make, duration_s, warning_C, trip_C = GRIDS[grid]
        pumps = make()
        for k in range(0, len(pumps), 9):
            name = f"{grid}{k // 9}"
            scenario, config = write_group(args.out, name, pumps[k:k + 9], duration_s,
                                           warning_C, trip_C, 20261201 + k)
            groups.append((grid, name, scenario, config))
    with concurrent.futures.ThreadPoolExecutor(max_workers=max(args.jobs, 1)) as pool:
        futures = [pool.submit(run_group, args, name, s, c) for _, name, s, c in groups]
        for i, fut in enumerate(concurrent.futures.as_completed(futures), 1):
            print(f"untuned_grid: {fut.result()} judged ({i}/{len(groups)})", file=sys.stderr)
    summary, misses = {}, []
    for grid in grids:
        rows = [r for g, name, _, _ in groups if g == grid for r in summarise(args.out, name)]
        summary[grid] = rows
        print_table(grid, rows)
        misses += missed(grid, rows)
    with open(os.path.join(args.out, "untuned_grid.json"), "w") as f:
        json.dump(summary, f, indent=1)
    if args.check and misses:
        print("\nuntuned_grid: goals missed:\n  " + "\n  ".join(misses))
        return 1
    if args.check:
        print("\nuntuned_grid: every goal met")
    return 0


if __name__ == "__main__":
    sys.exit(main())
