#!/usr/bin/env python3
"""tests/bench/ident_figures.py on hand-made CSVs whose figures were worked out by hand.

Truth, one row a second, t = 0..6 s: drive_state 1 1 2 2 2 2 2 (the run-up ends at 2 s), winding
40 40 50 50 60 60 50 degC. Window from 2 s: points 2..6 s, true 50 50 60 60 50, mean 54 degC.

DFRLS (`pumptherm identify --log`, status codes): rows at 0, 1.5, 2.5, 3.5, 4.5, 5.5 s with
27.2 (0), 45 (1), 52 (2), 57 (6 held), 58 (2), 49 (2). Sample and hold at the points:
  2 s <- 1.5 s: 45, error 5, converging;   3 s <- 2.5 s: 52, error 2, tracking;
  4 s <- 3.5 s: 57, error 3, held;         5 s <- 4.5 s: 58, error 2, tracking;
  6 s <- 5.5 s: 49, error 1, tracking.
  dT = 5 / 54 = 9.259 %, largest error while published 2 K, published 3 of 5 = 60 %.
  With --settle-s 2 (window from 4 s: true 60 60 50, mean 56.667): errors 3 (held), 2, 1:
  dT = 3 / 56.667 = 5.294 %, largest published 2 K, published 2 of 3 = 66.7 %.

Daemon CSV (published = a number; ident_status is not looked at): rows at 0.5,
1.5, 2.5, 3.5, 4.5, 5.5 s with nan nan nan 61 nan 53, ident_status `tracking` in every row.
  2 s, 3 s, 5 s: nan (not compared, not published); 4 s <- 3.5 s: 61, error 1; 6 s <- 5.5 s: 53,
  error 3. dT = 3 / 54 = 5.556 %, largest published 3 K, published 2 of 5 = 40 %.
"""
import contextlib
import importlib.util
import io
import os
import subprocess
import sys
import tempfile
import unittest

HERE = os.path.dirname(os.path.abspath(__file__))
spec = importlib.util.spec_from_file_location("ident_figures",
                                              os.path.join(HERE, "ident_figures.py"))
ident_figures = importlib.util.module_from_spec(spec)
spec.loader.exec_module(ident_figures)

TRUTH = """time_s,speed_rpm,winding_resistance_degC,drive_state
0,0,40,1
1,10000,40,1
2,21000,50,2
3,21000,50,2
4,21000,60,2
5,21000,60,2
6,21000,50,2
"""
DFRLS = """time_s,resistance_ohm,flux_Wb,winding_resistance_degC,status,winding_resistance_sd_K,flux_sd_Wb
0,0.28,0.0182,27.2,0,24,0.0009
1.5,0.3,0.0182,45,1,5,0.0001
2.5,0.3,0.0182,52,2,1,0.0001
3.5,0.3,0.0182,57,6,9,0.0001
4.5,0.3,0.0182,58,2,1,0.0001
5.5,0.3,0.0182,49,2,1,0.0001
"""
DAEMON = """time_s,frame_degC,winding_resistance_degC,ident_status,winding_resistance_sd_K
0.5,40,nan,tracking,nan
1.5,40,nan,tracking,nan
2.5,41,nan,tracking,nan
3.5,42,61,tracking,1.5
4.5,43,nan,tracking,nan
5.5,44,53,tracking,1.5
"""


class IdentFigures(unittest.TestCase):
    def setUp(self):
        self.dir = tempfile.TemporaryDirectory()
        self.paths = {}
        for name, text in (("truth", TRUTH), ("dfrls", DFRLS), ("daemon", DAEMON)):
            self.paths[name] = os.path.join(self.dir.name, name + ".csv")
            with open(self.paths[name], "w") as f:
                f.write(text)

    def tearDown(self):
        self.dir.cleanup()

    def judge(self, name, settle_s=0.0):
        return ident_figures.figures(ident_figures.read_truth(self.paths["truth"]),
                                     ident_figures.read_estimate(self.paths[name]), settle_s)

    def test_dfrls_published_only_while_tracking(self):
        f = self.judge("dfrls")
        self.assertEqual(f["window_s"], [2.0, 6.0])
        self.assertEqual(f["points"], 5)
        self.assertAlmostEqual(f["mean_true_degC"], 54.0)
        self.assertAlmostEqual(f["dT_pct"], 100.0 * 5.0 / 54.0)
        self.assertAlmostEqual(f["max_published_error_K"], 2.0)
        self.assertAlmostEqual(f["published_pct"], 60.0)

    def test_settle_moves_the_window(self):
        f = self.judge("dfrls", settle_s=2.0)
        self.assertEqual(f["window_s"], [4.0, 6.0])
        self.assertAlmostEqual(f["dT_pct"], 100.0 * 3.0 / (170.0 / 3.0))
        self.assertAlmostEqual(f["max_published_error_K"], 2.0)
        self.assertAlmostEqual(f["published_pct"], 200.0 / 3.0)

    def test_daemon_published_where_a_number(self):
        f = self.judge("daemon")
        self.assertEqual(f["compared_points"], 2)
        self.assertAlmostEqual(f["dT_pct"], 100.0 * 3.0 / 54.0)
        self.assertAlmostEqual(f["max_published_error_K"], 3.0)
        self.assertAlmostEqual(f["published_pct"], 40.0)

    def test_errors_name_the_file_and_the_missing_run_up(self):
        bad = os.path.join(self.dir.name, "bad.csv")
        with open(bad, "w") as f:
            f.write("time_s,winding_degC\n0,40\n")
        with self.assertRaises(SystemExit) as e:
            ident_figures.read_estimate(bad)
        self.assertIn("bad.csv: no column winding_resistance_degC", str(e.exception))
        still = os.path.join(self.dir.name, "still.csv")
        with open(still, "w") as f:
            f.write("time_s,winding_resistance_degC,drive_state\n0,40,0\n1,40,1\n")
        with self.assertRaises(SystemExit) as e:
            ident_figures.figures(ident_figures.read_truth(still),
                                  ident_figures.read_estimate(self.paths["dfrls"]))
        self.assertIn("never reaches drive_state 2", str(e.exception))

    def test_command_line_prints_the_table(self):
        out = subprocess.run(
            [sys.executable, os.path.join(HERE, "ident_figures.py"), "--truth",
             self.paths["truth"], "dfrls=" + self.paths["dfrls"], "daemon=" + self.paths["daemon"],
             "--json", os.path.join(self.dir.name, "f.json")],
            check=True, capture_output=True, text=True).stdout
        self.assertIn("| truth.csv | dfrls | 2-6 | 9.26 | 2.00 | 60.0 |", out)
        self.assertIn("| truth.csv | daemon | 2-6 | 5.56 | 3.00 | 40.0 |", out)
        self.assertTrue(os.path.exists(os.path.join(self.dir.name, "f.json")))


if __name__ == "__main__":
    unittest.main()
