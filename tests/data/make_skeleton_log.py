#!/usr/bin/env python3
"""Writes skeleton.log: a small, deterministic candump log for the walking-skeleton tests.

Two pump drives (node IDs 1 and 2) on can0 for 10 s: fast telemetry at 100 Hz (CAN ID
0x180 + node), slow status at 10 Hz (0x280 + node), and a 29-bit diagnostic frame at 1 Hz,
with up to 300 us of timing jitter. Payloads are arbitrary but fixed (seeded). The plant
simulator (`pumptherm plant`) writes physically meaningful recordings.
"""
import random

rng = random.Random(20261122)
t0 = 1763776800.0
events = []
for node in (1, 2):
    for k in range(1000):
        events.append((t0 + k * 0.01 + node * 0.0013 + rng.uniform(0, 3e-4), "%03X" % (0x180 + node), 8))
    for k in range(100):
        events.append((t0 + k * 0.1 + node * 0.0051 + rng.uniform(0, 3e-4), "%03X" % (0x280 + node), 6))
for k in range(10):
    events.append((t0 + k + 0.0077, "18FF5001", 8))
events.sort()
with open("skeleton.log", "w") as f:
    for t, cid, n in events:
        data = "".join("%02X" % rng.randrange(256) for _ in range(n))
        f.write("(%.6f) can0 %s#%s\n" % (t, cid, data))
