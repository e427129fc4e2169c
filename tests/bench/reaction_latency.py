#!/usr/bin/env python3
"""The live reaction of the gateway, from a candump capture of its bus.

Reads a capture in candump's log format (`candump -L`, kernel receive stamps; plain or .gz) that
holds the pumps' telemetry and the gateway's GW_NODE_TEMP and GW_ALARM frames, as
tests/vcan/daemon_full_bus_latency.sh records it, and reports per pump and over all pumps the
delay from the telemetry frame that completes a thermal period to the first GW_NODE_TEMP and the
first GW_ALARM of that pump that follow it, and how late those frames were against their own
schedule. The definitions (docs/robustness.md, "Live reaction"):

- Pump n's frames are the DBC's PUMP_FAST_I, PUMP_FAST_U and PUMP_STATUS IDs + n; its outputs
  GW_NODE_TEMP + n and GW_ALARM + n (the mapping's node IDs).
- The daemon steps a pump's thermal period on frame time: the first step is due one period after
  the pump's first frame (daemon/pump.cpp, Pump::Advance), so boundary k is B_k = F + k * T, F the
  stamp of the pump's first frame in the capture, T = --period-s. The frame that completes period
  k is the pump's first frame stamped at or after B_k (a boundary whose next frame comes a whole
  period or more later, a silence, is skipped and counted).
- The answer to it: the pump's first GW_NODE_TEMP and first GW_ALARM stamped at or after that
  frame. delay = answer - completing frame.
- The outputs go out on their own schedule (daemon/gateway.cpp, AdvancePump): a grid of their
  period (GW_ALARM: its DBC cycle time; GW_NODE_TEMP: its cycle time divided by the model's
  nodes, one node after another), re-anchored when the daemon fell a whole period behind; a
  GW_ALARM sent at once on a change takes the next slot. So a delay is the wait for the next slot
  (by design up to one output period) plus the lateness: answer - its slot. "Beyond the
  schedule" is that lateness. The slots are not on the bus: the grid's phase is taken from its
  most punctual frame (no scheduled frame leaves before its slot; schedule_lateness), so a
  lateness is relative to that frame's, which includes at least the send itself. A GW_ALARM
  whose alarm fields changed may have left before its slot: it is not timed.

Percentiles are nearest-rank. Exits 1, naming what is missing, on a capture without telemetry or
without a single GW_NODE_TEMP or GW_ALARM, or with a pump that has telemetry and no outputs.
Standard library only.

Example:
  tests/bench/reaction_latency.py build/tests/vcan/full_bus_latency-out/bus.log.gz \\
      --dbc protocol/pumptherm.dbc
"""
import argparse
import bisect
import gzip
import json
import math
import re
import sys

INPUTS = ("PUMP_FAST_I", "PUMP_FAST_U", "PUMP_STATUS")
OUTPUTS = ("GW_NODE_TEMP", "GW_ALARM")
# The GW_ALARM signals whose change makes the daemon send it at once (Gateway::AdvancePump).
ALARM_SIGNALS = ("AlarmLevel", "AlarmReason", "AlarmNode")


class CaptureError(Exception):
    pass


def read_dbc(path):
    """Returns {message name: (id, cycle time in us or None)} for the messages we need, and
    {signal: (start bit, length)} of GW_ALARM's alarm signals (little-endian)."""
    ids, cycles, alarm_bits, message = {}, {}, {}, None
    with open(path, encoding="utf-8", errors="replace") as f:
        for line in f:
            m = re.match(r"\s*BO_\s+(\d+)\s+(\w+)\s*:", line)
            if m:
                ids[m.group(2)] = int(m.group(1))
                message = m.group(2)
                continue
            m = re.match(r"\s*SG_\s+(\w+)\s*:\s*(\d+)\|(\d+)@1", line)
            if m and message == "GW_ALARM" and m.group(1) in ALARM_SIGNALS:
                alarm_bits[m.group(1)] = (int(m.group(2)), int(m.group(3)))
                continue
            m = re.match(r'\s*BA_\s+"GenMsgCycleTime"\s+BO_\s+(\d+)\s+(\d+)\s*;', line)
            if m:
                cycles[int(m.group(1))] = int(m.group(2)) * 1000
    out = {}
    for name in INPUTS + OUTPUTS:
        if name not in ids:
            raise CaptureError(f"{path}: no message {name}")
        out[name] = (ids[name], cycles.get(ids[name]))
    missing = [n for n in ALARM_SIGNALS if n not in alarm_bits]
    if missing:
        raise CaptureError(f"{path}: GW_ALARM has no little-endian {', '.join(missing)}")
    return out, alarm_bits


def read_capture(path):
    """Returns [(stamp_us, can_id, data)] in file order; stamps as integer microseconds, data as
    an int (byte 0 least significant)."""
    opener = gzip.open if path.endswith(".gz") else open
    frames = []
    line_re = re.compile(r"\((\d+)\.(\d{6})\)\s+\S+\s+([0-9A-Fa-f]+)#([0-9A-Fa-f]*)")
    with opener(path, "rt", encoding="ascii", errors="replace") as f:
        for number, line in enumerate(f, 1):
            if not line.strip():
                continue
            m = line_re.match(line)
            if not m:
                raise CaptureError(f"{path}:{number}: not a candump -L line: {line.strip()[:60]!r}")
            data = int.from_bytes(bytes.fromhex(m.group(4)), "little") if len(m.group(4)) % 2 == 0 else 0
            frames.append((int(m.group(1)) * 1_000_000 + int(m.group(2)), int(m.group(3), 16), data))
    return frames


def percentile(values, p):
    """Nearest rank: the smallest value with at least p % of the values at or below it."""
    s = sorted(values)
    return s[max(0, math.ceil(p / 100.0 * len(s)) - 1)]


def schedule_lateness(frames, period_us, on_change):
    """Lateness of a pump's frames of one output message against the daemon's grid for it.

    `frames`: [(stamp_us, data)] in time order; `on_change(previous data, data)`: whether a frame
    may have been sent at once on a change (GW_ALARM whose alarm fields changed). The daemon
    (Gateway::AdvancePump) emits a frame when its slot has come, or at once on an alarm change;
    either way the next slot is one period on, unless the daemon was a whole period behind: then
    it is one period after that emission (re-anchored). So within a stretch between
    re-anchorings frame i (counted from the stretch's start) has slot anchor + i * period, and
    no scheduled frame goes out before its slot: the anchor is the smallest stamp - i * period
    of the stretch's scheduled frames (for a re-anchored stretch also the re-anchoring frame's
    stamp, the daemon's time then). Returns ({stamp: lateness_us} of the scheduled frames,
    frames sent on a change, re-anchorings)."""
    stretches, start, base, running = [], 0, frames[0][0], None
    changed = [i > 0 and on_change(frames[i - 1][1], frames[i][1]) for i in range(len(frames))]
    for i, (t, _) in enumerate(frames):
        offset = t - (i - start) * period_us
        if not changed[i]:
            running = offset if running is None else min(running, offset)
        if running is not None and offset - running >= period_us:
            stretches.append((start, i + 1, base))
            # The next slot is one period after the daemon's time of this emission (<= t).
            start, base, running = i + 1, t + period_us, t + period_us
    stretches.append((start, len(frames), base))
    lateness = {}
    for start, end, base in stretches:
        offsets = [frames[i][0] - (i - start) * period_us for i in range(start, end) if not changed[i]]
        anchor = min(offsets + ([base] if start > 0 else []), default=base)
        for i in range(start, end):
            if not changed[i]:
                lateness[frames[i][0]] = frames[i][0] - (i - start) * period_us - anchor
    return lateness, sum(changed), len(stretches) - 1


def analyse(frames, dbc, alarm_bits, period_us, model_nodes, node_ids=range(16)):
    """Per pump: boundaries and, per output, [(delay_us, lateness_us)]; plus stream counters."""
    first = lambda name: dbc[name][0]  # noqa: E731
    periods = {}
    for name in OUTPUTS:
        cycle = dbc[name][1] or 1_000_000
        periods[name] = max(1000, cycle // model_nodes) if name == "GW_NODE_TEMP" else cycle
    by_id = {}
    for t, i, data in frames:
        by_id.setdefault(i, []).append((t, data))
    pumps = {}
    saw_output = {name: 0 for name in OUTPUTS}
    for n in node_ids:
        inputs = sorted(t for m in INPUTS for t, _ in by_id.get(first(m) + n, []))
        if not inputs:
            continue
        outs = {name: sorted(by_id.get(first(name) + n, [])) for name in OUTPUTS}
        for name in OUTPUTS:
            saw_output[name] += len(outs[name])
        pumps[n] = (inputs, outs)
    if not pumps:
        raise CaptureError("no pump telemetry (PUMP_FAST_I, PUMP_FAST_U, PUMP_STATUS) in the capture")
    for name in OUTPUTS:
        if saw_output[name] == 0:
            raise CaptureError(f"no {name} frame in the capture: the gateway sent nothing (or "
                               f"candump did not record its output)")
    def alarm_changed(a, b):
        return any((a >> start) & ((1 << length) - 1) != (b >> start) & ((1 << length) - 1)
                   for start, length in alarm_bits.values())

    result = {}
    for n, (inputs, outs) in pumps.items():
        for name in OUTPUTS:
            if not outs[name]:
                raise CaptureError(f"pump node {n}: telemetry but no {name} frame")
        late = {"GW_NODE_TEMP": schedule_lateness(outs["GW_NODE_TEMP"], periods["GW_NODE_TEMP"],
                                                  lambda a, b: False),
                "GW_ALARM": schedule_lateness(outs["GW_ALARM"], periods["GW_ALARM"], alarm_changed)}
        outs = {name: [t for t, _ in outs[name]] for name in OUTPUTS}
        rows = {name: [] for name in OUTPUTS}
        boundaries = skipped = unanswered = 0
        k = 1
        j = 0
        while inputs[0] + k * period_us <= inputs[-1]:
            b = inputs[0] + k * period_us
            while inputs[j] < b:
                j += 1
            c = inputs[j]
            k += 1
            if c >= b + period_us:
                skipped += 1
                continue
            boundaries += 1
            for name in OUTPUTS:
                a = bisect.bisect_left(outs[name], c)
                if a == len(outs[name]):
                    unanswered += 1
                    continue
                answer = outs[name][a]
                rows[name].append((answer - c, late[name][0].get(answer)))
        result[n] = {
            "boundaries": boundaries, "skipped": skipped, "unanswered": unanswered,
            "rows": rows,
            "stream": {name: {"lateness": list(late[name][0].values()), "early": late[name][1],
                              "rephased": late[name][2], "frames": len(outs[name])}
                       for name in OUTPUTS},
        }
    return result, periods


def summary(values):
    if not values:
        return None
    return {"n": len(values), "p50": percentile(values, 50), "p99": percentile(values, 99),
            "max": max(values)}


def ms(us):
    return f"{us / 1000:.1f}"


def report(result, periods, out):
    header = (f"{'pump':>4} {'periods':>7} "
              + " ".join(f"{n + ' ' + w:>28}" for n in ("NODE_TEMP", "ALARM")
                         for w in ("delay ms p50/p99/max", "late ms p50/p99/max")))
    print(header, file=out)
    every = {(name, w): [] for name in OUTPUTS for w in (0, 1)}

    def cells(rows):
        text = []
        for name in OUTPUTS:
            for w in (0, 1):
                v = [r[w] for r in rows[name] if r[w] is not None]
                every[(name, w)].extend(v)
                s = summary(v)
                text.append(f"{'-' if s is None else '/'.join(ms(s[k]) for k in ('p50', 'p99', 'max')):>28}")
        return " ".join(text)

    for n in sorted(result):
        r = result[n]
        print(f"{n:>4} {r['boundaries']:>7} {cells(r['rows'])}", file=out)
    total = sum(r["boundaries"] for r in result.values())
    line = []
    figures = {"periods": total,
               "skipped": sum(r["skipped"] for r in result.values()),
               "unanswered": sum(r["unanswered"] for r in result.values()),
               "output_period_ms": {k: v / 1000 for k, v in periods.items()}}
    for name in OUTPUTS:
        for w, what in ((0, "delay"), (1, "late")):
            s = summary(every[(name, w)])
            figures[f"{name}_{what}_ms"] = None if s is None else {k: (s[k] / 1000 if k != "n" else s[k]) for k in s}
            line.append(f"{'-' if s is None else '/'.join(ms(s[k]) for k in ('p50', 'p99', 'max')):>28}")
    print(f"{'all':>4} {total:>7} {' '.join(line)}", file=out)
    for name in OUTPUTS:
        lat = [v for r in result.values() for v in r["stream"][name]["lateness"]]
        s = summary(lat)
        early = sum(r["stream"][name]["early"] for r in result.values())
        rephased = sum(r["stream"][name]["rephased"] for r in result.values())
        frames = sum(r["stream"][name]["frames"] for r in result.values())
        figures[f"{name}_every_frame_late_ms"] = {k: (s[k] / 1000 if k != "n" else s[k]) for k in s}
        print(f"{name}: {frames} frames, every {periods[name] / 1000:g} ms per pump; late against "
              f"the schedule p50/p99/max {'/'.join(ms(s[k]) for k in ('p50', 'p99', 'max'))} ms; "
              f"{early} with a changed alarm (maybe sent at once: not timed); {rephased} "
              f"re-anchorings (the daemon a whole period behind)",
              file=out)
    print(f"periods skipped (no frame within a period of the boundary): {figures['skipped']}; "
          f"answers missing at the end of the capture: {figures['unanswered']}", file=out)
    return figures


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog=__doc__.split("\n\n", 1)[1])
    ap.add_argument("capture", help="candump -L capture (.gz allowed)")
    ap.add_argument("--dbc", required=True, help="the DBC (IDs and cycle times)")
    ap.add_argument("--period-s", type=float, default=1.0,
                    help="gateway.thermal_period_s (default 1.0)")
    ap.add_argument("--model-nodes", type=int, default=4,
                    help="nodes of the pumps' thermal model (GW_NODE_TEMP's period is the cycle "
                         "time over this; default 4, tmp-generic)")
    ap.add_argument("--json", help="also write the figures here")
    a = ap.parse_args(argv)
    try:
        dbc, alarm_bits = read_dbc(a.dbc)
        frames = read_capture(a.capture)
        if not frames:
            raise CaptureError(f"{a.capture}: no frame")
        result, periods = analyse(frames, dbc, alarm_bits, round(a.period_s * 1e6), a.model_nodes)
    except (CaptureError, OSError) as e:
        print(f"reaction_latency: error: {e}", file=sys.stderr)
        return 1
    figures = report(result, periods, sys.stdout)
    if a.json:
        with open(a.json, "w") as f:
            json.dump(figures, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
