#!/usr/bin/env python3
"""Can the voltages of a Paderborn profile give the winding from its resistance, or the magnet
from its flux? (docs/virtual-sensor.md, "Real data: Paderborn profile 46")

Fits the steady-state dq voltage equations of a PMSM with saliency,
    u_q = R_s i_q + w (L_d i_d + psi),   u_d = R_s i_d - w L_q i_q,
by least squares over every row, first with constant parameters, then with the measured
temperatures given (R_s = R_20 (1 + alpha (T_winding - 20)), copper alpha 0.00393 1/K, and
psi = psi_20 + dpsi (T_pm - 20)): the most that any identifier on these voltages could explain.
The residual left, over what 1 K of winding (R_20 alpha |i_q|) or of magnet (0.1 % of w psi, an
NdFeB magnet) moves u_q, is the temperature error that residual alone stands for. The pole-pair
count only rescales L and psi (w is taken as 2 pi n / 60 x 4); the voltage figures do not depend
on it. Pure Python, no third-party packages.

Usage: paderborn_voltage_check.py [CSV]  (default: ../shared/data/paderborn/profile46_every10th_dt5s.csv
from the checkout's parent)
"""
import csv
import math
import os
import sys

ALPHA_CU = 0.00393  # 1/K, annealed copper at 20 degC
NDFEB = 0.001  # relative flux change per K (magnitude)
POLE_PAIRS = 4  # a scale only (see above)


def least_squares(rows, y):
    """Solves the normal equations by Gauss-Jordan elimination; returns (x, rms residual)."""
    k = len(rows[0])
    m = [[sum(r[i] * r[j] for r in rows) for j in range(k)] + [sum(r[i] * v for r, v in zip(rows, y))]
         for i in range(k)]
    for c in range(k):
        p = max(range(c, k), key=lambda r: abs(m[r][c]))
        m[c], m[p] = m[p], m[c]
        for r in range(k):
            if r != c:
                f = m[r][c] / m[c][c]
                m[r] = [a - f * b for a, b in zip(m[r], m[c])]
    x = [m[i][k] / m[i][i] for i in range(k)]
    res = [v - sum(a * b for a, b in zip(r, x)) for r, v in zip(rows, y)]
    return x, math.sqrt(sum(e * e for e in res) / len(res))


def median(v):
    s = sorted(v)
    return s[len(s) // 2]


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    default = os.path.normpath(os.path.join(here, "..", "..", "..", "shared", "data", "paderborn",
                                            "profile46_every10th_dt5s.csv"))
    path = sys.argv[1] if len(sys.argv) > 1 else default
    try:
        rows = list(csv.DictReader(open(path, encoding="utf-8")))
    except OSError as e:
        sys.exit(f"paderborn_voltage_check: {e}")
    col = lambda k: [float(r[k]) for r in rows]
    uq, ud, iq, id_, n = col("u_q"), col("u_d"), col("i_q"), col("i_d"), col("motor_speed")
    tw, pm = col("stator_winding"), col("pm")
    w = [2.0 * math.pi * v / 60.0 * POLE_PAIRS for v in n]
    idx = range(len(rows))
    q_const, q_rms = least_squares([[iq[i], w[i] * id_[i], w[i]] for i in idx], uq)
    d_const, d_rms = least_squares([[id_[i], -w[i] * iq[i]] for i in idx], ud)
    q_temp, q_temp_rms = least_squares(
        [[iq[i] * (1 + ALPHA_CU * (tw[i] - 20)), w[i] * id_[i], w[i], w[i] * (pm[i] - 20)] for i in idx],
        uq)
    d_temp, d_temp_rms = least_squares(
        [[id_[i] * (1 + ALPHA_CU * (tw[i] - 20)), -w[i] * iq[i]] for i in idx], ud)
    r20 = q_temp[0]
    winding_V_per_K = r20 * ALPHA_CU * median([abs(v) for v in iq])
    magnet_V_per_K = NDFEB * q_temp[2] * median(w)
    print(f"{path}: {len(rows)} rows, {min(n):.0f}-{max(n):.0f} r/min, i_q {min(iq):.0f}..{max(iq):.0f} A, "
          f"i_d {min(id_):.0f}..{max(id_):.0f} A")
    print("| fit | parameters | rms residual |")
    print("| --- | --- | --- |")
    print(f"| u_q, constant | R_s {q_const[0] * 1e3:.1f} mOhm, L_d {q_const[1] * 1e6:.0f} uH, psi {q_const[2] * 1e3:.1f} mWb "
          f"| {q_rms:.2f} V |")
    print(f"| u_d, constant | R_s {d_const[0] * 1e3:.1f} mOhm, L_q {d_const[1] * 1e6:.0f} uH | {d_rms:.2f} V |")
    print(f"| u_q, measured temperatures given | R_20 {r20 * 1e3:.1f} mOhm, psi {q_temp[2] * 1e3:.1f} mWb, "
          f"dpsi/psi {100 * q_temp[3] / q_temp[2]:+.3f} %/K | {q_temp_rms:.2f} V |")
    print(f"| u_d, measured winding given | R_20 {d_temp[0] * 1e3:.1f} mOhm | {d_temp_rms:.2f} V |")
    print(f"1 K of winding moves u_q by {winding_V_per_K * 1e3:.1f} mV at the median |i_q|: the u_q residual "
          f"stands for {q_temp_rms / winding_V_per_K:.0f} K of winding")
    print(f"1 K of magnet (0.1 %/K) moves u_q by {magnet_V_per_K * 1e3:.0f} mV at the median speed: the "
          f"residual stands for {q_temp_rms / magnet_V_per_K:.1f} K of magnet")


if __name__ == "__main__":
    main()
