#!/usr/bin/env python3
"""tests/bench/reaction_latency.py on a hand-made capture whose answer was worked out by hand.

The DBC here gives GW_ALARM a 500 ms cycle and GW_NODE_TEMP 1000 ms; with --model-nodes 2 both
go out every 500 ms. Thermal period 1 s.

Pump 0: first frame 100.000, so the boundaries are 101.000 and 102.000 (the next, 103.000, is
after its last frame). 101.004 completes the first period, 102.002 the second.
  GW_NODE_TEMP 100.001, .501, 101.001, 101.503 (2 ms late), 102.0015 (0.5 ms late), 102.510
  (9 ms late): 101.004 is answered by 101.503 (499 ms, 2 ms late), 102.002 by 102.510 (508 ms,
  9 ms late).
  GW_ALARM 100.002, .502, 101.002, 101.200 (the alarm level changed: sent at once, it takes the
  slot 101.502 and is not timed), 102.002, 102.502: 101.004 is answered by 101.200 (196 ms),
  102.002 by 102.002 itself (0 ms, on time).
Pump 1: first frame 100.100; nothing from 100.500 until 102.300: boundary 101.100 has no frame
within a period (skipped), boundary 102.100 is completed by 102.300.
  GW_NODE_TEMP 100.101, .601, 101.900 (slot 101.101: 799 ms late, more than a period: the daemon
  re-anchors at 101.900 + 0.5), 102.400 (on time): 102.300 answered in 100 ms.
  GW_ALARM every 500 ms from 100.102, on time: 102.300 answered by 102.602 (302 ms).
Pump 2: first frame 100.000, boundary 101.000 completed by 101.001.
  GW_NODE_TEMP 100.004 (3 ms late: the grid's phase comes from the punctual frames after it),
  100.501, 101.001, 101.501: 101.001 answered by 101.001 (0 ms, on time).
  GW_ALARM 100.002, .502, 101.002, 101.502: 101.001 answered by 101.002 (1 ms).
All pumps: NODE_TEMP delays 0, 100, 499, 508 ms: nearest-rank p50 100, p99 508; late 0, 0, 2,
9 ms. ALARM delays 0, 1, 196, 302 ms: p50 1, p99 302; late 0, 0, 0 (the on-change answer is not
timed). Every NODE_TEMP frame's lateness (14 frames): nine 0, then 0.5, 2, 3, 9 and 799 ms:
p50 0, p99 = max = 799 ms.
"""
import contextlib
import gzip
import importlib.util
import io
import os
import sys
import tempfile
import unittest

HERE = os.path.dirname(os.path.abspath(__file__))
spec = importlib.util.spec_from_file_location("reaction_latency",
                                              os.path.join(HERE, "reaction_latency.py"))
rl = importlib.util.module_from_spec(spec)
spec.loader.exec_module(rl)

DBC = """VERSION ""
BO_ 256 PUMP_FAST_I: 8 Drive
BO_ 272 PUMP_FAST_U: 8 Drive
BO_ 384 PUMP_STATUS: 8 Drive
BO_ 1152 GW_NODE_TEMP: 8 Gateway
BO_ 512 GW_ALARM: 8 Gateway
 SG_ AlarmLevel : 0|2@1+ (1,0) [0|2] "" Monitor
 SG_ AlarmReason : 2|6@1+ (1,0) [0|62] "" Monitor
 SG_ AlarmNode : 8|4@1+ (1,0) [0|14] "" Monitor
 SG_ RollingCounter : 56|4@1+ (1,0) [0|15] "" Monitor
BA_ "GenMsgCycleTime" BO_ 512 500;
BA_ "GenMsgCycleTime" BO_ 1152 1000;
"""

ALARM_OK = "0000FFFFFFFF0000"
ALARM_WARNING = "0100FFFFFFFF0000"  # AlarmLevel 1
FRAMES = [  # (stamp, hex ID[, data])
    # pump 0
    ("100.000000", "100"), ("100.600000", "180"), ("101.004000", "110"), ("101.700000", "100"),
    ("102.002000", "100"), ("102.300000", "180"),
    ("100.001000", "480"), ("100.501000", "480"), ("101.001000", "480"), ("101.503000", "480"),
    ("102.001500", "480"), ("102.510000", "480"),
    ("100.002000", "200", ALARM_OK), ("100.502000", "200", ALARM_OK),
    ("101.002000", "200", ALARM_OK), ("101.200000", "200", ALARM_WARNING),
    ("102.002000", "200", ALARM_WARNING), ("102.502000", "200", ALARM_WARNING),
    # pump 1
    ("100.100000", "101"), ("100.500000", "181"), ("102.300000", "101"), ("102.400000", "111"),
    ("100.101000", "481"), ("100.601000", "481"), ("101.900000", "481"), ("102.400000", "481"),
    ("100.102000", "201"), ("100.602000", "201"), ("101.102000", "201"), ("101.602000", "201"),
    ("102.102000", "201"), ("102.602000", "201"),
    # pump 2
    ("100.000000", "102"), ("101.001000", "102"),
    ("100.004000", "482"), ("100.501000", "482"), ("101.001000", "482"), ("101.501000", "482"),
    ("100.002000", "202"), ("100.502000", "202"), ("101.002000", "202"), ("101.502000", "202"),
]


def capture_text(frames):
    # candump -L, in time order as candump writes it.
    return "".join(f"({f[0]}) vcan0 {f[1]}#{f[2] if len(f) > 2 else ALARM_OK}\n" for f in sorted(frames))


class ReactionLatencyTest(unittest.TestCase):
    def setUp(self):
        self.dir = tempfile.TemporaryDirectory()
        self.dbc = self.path("t.dbc", DBC)

    def tearDown(self):
        self.dir.cleanup()

    def path(self, name, text):
        p = os.path.join(self.dir.name, name)
        with (gzip.open(p, "wt") if name.endswith(".gz") else open(p, "w")) as f:
            f.write(text)
        return p

    def run_main(self, capture, *extra):
        out, err = io.StringIO(), io.StringIO()
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            rc = rl.main([capture, "--dbc", self.dbc, "--model-nodes", "2", *extra])
        return rc, out.getvalue(), err.getvalue()

    def test_hand_computed_capture(self):
        capture = self.path("bus.log.gz", capture_text(FRAMES))
        json_path = os.path.join(self.dir.name, "f.json")
        rc, out, err = self.run_main(capture, "--json", json_path)
        self.assertEqual(rc, 0, err)
        import json
        with open(json_path) as f:
            fig = json.load(f)
        msg = out
        self.assertEqual(fig["periods"], 4, msg)
        self.assertEqual(fig["skipped"], 1, msg)
        self.assertEqual(fig["unanswered"], 0, msg)
        self.assertEqual(fig["output_period_ms"], {"GW_NODE_TEMP": 500.0, "GW_ALARM": 500.0})
        self.assertEqual(fig["GW_NODE_TEMP_delay_ms"], {"n": 4, "p50": 100.0, "p99": 508.0, "max": 508.0}, msg)
        self.assertEqual(fig["GW_NODE_TEMP_late_ms"], {"n": 4, "p50": 0.0, "p99": 9.0, "max": 9.0}, msg)
        self.assertEqual(fig["GW_ALARM_delay_ms"], {"n": 4, "p50": 1.0, "p99": 302.0, "max": 302.0}, msg)
        self.assertEqual(fig["GW_ALARM_late_ms"], {"n": 3, "p50": 0.0, "p99": 0.0, "max": 0.0}, msg)
        self.assertEqual(fig["GW_NODE_TEMP_every_frame_late_ms"],
                         {"n": 14, "p50": 0.0, "p99": 799.0, "max": 799.0}, msg)
        self.assertIn("1 re-anchorings", out)
        self.assertIn("GW_ALARM: 16 frames", out)
        self.assertIn("1 with a changed alarm", out)
        self.assertIn("GW_NODE_TEMP: 14 frames", out)

    def test_schedule_of_one_message(self):
        def us(t):
            return int(t.replace(".", ""))

        def stream(node_id):
            data = lambda f: bytes.fromhex(f[2] if len(f) > 2 else ALARM_OK)  # noqa: E731
            return [(us(f[0]), int.from_bytes(data(f), "little")) for f in sorted(FRAMES)
                    if f[1] == node_id]

        never = lambda a, b: False  # noqa: E731
        # Pump 2's first GW_NODE_TEMP is 3 ms late: the phase comes from the punctual ones.
        late, changed, rephased = rl.schedule_lateness(stream("482"), 500_000, never)
        self.assertEqual(sorted(late.values()), [0, 0, 0, 3000])
        self.assertEqual(late[us("100.004000")], 3000)
        self.assertEqual((changed, rephased), (0, 0))
        # Pump 1's 799 ms late frame re-anchors the grid; the next frame is on time.
        late, changed, rephased = rl.schedule_lateness(stream("481"), 500_000, never)
        self.assertEqual(late, {us("100.101000"): 0, us("100.601000"): 0, us("101.900000"): 799_000,
                                us("102.400000"): 0})
        self.assertEqual((changed, rephased), (0, 1))
        # Pump 0's alarm change at 101.200 is not timed and takes the slot 101.502.
        late, changed, rephased = rl.schedule_lateness(stream("200"), 500_000,
                                                       lambda a, b: (a & 3) != (b & 3))
        self.assertNotIn(us("101.200000"), late)
        self.assertEqual(set(late.values()), {0})
        self.assertEqual((changed, rephased), (1, 0))

    def test_no_outputs_fails_loudly(self):
        inputs_only = [f for f in FRAMES if f[1].startswith("1")]
        rc, out, err = self.run_main(self.path("in.log", capture_text(inputs_only)))
        self.assertEqual(rc, 1)
        self.assertIn("no GW_NODE_TEMP frame in the capture", err)
        self.assertEqual(out, "")

    def test_pump_without_outputs_fails(self):
        no_pump1_out = [f for f in FRAMES if f[1] not in ("481", "201")]
        rc, _, err = self.run_main(self.path("p.log", capture_text(no_pump1_out)))
        self.assertEqual(rc, 1)
        self.assertIn("pump node 1: telemetry but no GW_NODE_TEMP frame", err)

    def test_empty_and_malformed_captures(self):
        rc, _, err = self.run_main(self.path("e.log", ""))
        self.assertEqual(rc, 1)
        self.assertIn("no frame", err)
        bad = self.path("b.log", "(100.000000) vcan0 100#00\n 100  [8] 00 00\n")
        rc, _, err = self.run_main(bad)
        self.assertEqual(rc, 1)
        self.assertIn("b.log:2: not a candump -L line", err)


if __name__ == "__main__":
    unittest.main(verbosity=1)
