#!/usr/bin/env python3
"""Writes seed inputs for pipeline_step_fuzz (record format in pipeline_step_fuzz.cpp): a pump of
the shipped DBC (node 1) running at a few operating points, 100 Hz fast frames, 10 Hz status.

    make_pipeline_seeds.py OUT_DIR
"""
import math
import struct
import sys

PSI_WB, R_OHM, L_H, POLE_PAIRS = 0.0182, 0.28, 0.24e-3, 1


def signed16(x, scale):
    return struct.pack("<h", max(-32767, min(32767, round(x / scale))))


def fast_i(id_a, iq_a, w_e, counter):
    raw_w = max(0, min(0xFFFFFE, round(w_e / 0.01)))
    return signed16(id_a, 0.005) + signed16(iq_a, 0.005) + struct.pack("<I", raw_w)[:3] + bytes([counter & 0xF])


def fast_u(ud_v, uq_v, counter):
    return signed16(ud_v, 0.002) + signed16(uq_v, 0.002) + b"\0\0\0" + bytes([counter & 0xF])


def status(speed_rpm, state, frame_c, ambient_c, counter):
    bits = round(speed_rpm / 2) & 0xFFFF
    bits |= (state & 0x7) << 16
    bits |= (round((frame_c + 50) / 0.1) & 0xFFF) << 19
    bits |= (round((ambient_c + 50) / 0.1) & 0xFFF) << 31
    bits |= (round(48 / 0.05) & 0xFFF) << 43
    bits |= (counter & 0xF) << 56
    return struct.pack("<Q", bits)


def record(selector, dt_ms, payload):
    return bytes([selector]) + struct.pack("<H", dt_ms) + bytes([len(payload)]) + payload


def seed(seconds, speed_rpm, iq_a, frame_c, clear_at_s=None):
    out = bytearray()
    w_e = speed_rpm * 2 * math.pi / 60 * POLE_PAIRS
    for k in range(seconds * 100):
        c = k & 0xF
        id_a = 0.5 * math.sin(k / 7.0)  # some excitation on d
        ud = R_OHM * id_a - w_e * L_H * iq_a
        uq = R_OHM * iq_a + w_e * L_H * id_a + w_e * PSI_WB
        out += record(0, 10, fast_i(id_a, iq_a, w_e, c))
        out += record(1, 0, fast_u(ud, uq, c))
        if k % 10 == 0:
            out += record(2, 0, status(speed_rpm, 2, frame_c + k * 0.002, 25.0, c))
        if clear_at_s is not None and k == clear_at_s * 100:
            out += record(3, 0, b"\x01")
    return bytes(out)


def main():
    out_dir = sys.argv[1]
    cases = {
        "idle": seed(2, 0, 0.0, 25.0),
        "run": seed(3, 800, 10.0, 40.0),
        "hot": seed(4, 24000, 40.0, 150.0, clear_at_s=2),
    }
    for name, data in cases.items():
        with open(f"{out_dir}/pipeline_{name}", "wb") as f:
            f.write(data)


if __name__ == "__main__":
    main()
