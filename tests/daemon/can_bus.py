#!/usr/bin/env python3
"""The bus side of the CAN shim (tests/daemon/can_shim/can_shim.c) for host-side daemon tests.

    can_bus.py DIR IFACE --record OUT [--replay LOG] [--duration S]

Binds DIR/IFACE.bus (where the shimmed daemon sends), records every frame the daemon sends as
"t_s id_hex len data_hex" lines into OUT (t_s: when the daemon sent it, CLOCK_MONOTONIC, which
the shim appends), and replays a candump log (its
frames of any interface, at their recorded pace, looping) into DIR/IFACE.gw, the daemon's
socket. Stops after --duration seconds, or on SIGTERM; prints how many frames went each way.
"""
import argparse
import os
import signal
import socket
import struct
import threading
import time

CAN_EFF_FLAG = 0x80000000


def read_candump(path):
    """(t_s, can_id with EFF flag, data) of every frame line of a candump -l log."""
    frames = []
    with open(path) as f:
        for line in f:
            parts = line.split()
            if len(parts) != 3 or not parts[0].startswith("("):
                continue
            t = float(parts[0].strip("()"))
            ident, _, data = parts[2].partition("#")
            if data.startswith("R"):
                continue
            can_id = int(ident, 16) | (CAN_EFF_FLAG if len(ident) > 3 else 0)
            frames.append((t, can_id, bytes.fromhex(data)))
    return frames


def frame_bytes(can_id, data):
    return struct.pack("<IB3x8s", can_id, len(data), data.ljust(8, b"\0"))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("dir")
    ap.add_argument("iface")
    ap.add_argument("--record", required=True)
    ap.add_argument("--replay")
    ap.add_argument("--duration", type=float, default=3600.0)
    args = ap.parse_args()

    bus_path = os.path.join(args.dir, args.iface + ".bus")
    gw_path = os.path.join(args.dir, args.iface + ".gw")
    try:
        os.unlink(bus_path)
    except FileNotFoundError:
        pass
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(bus_path)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    received = [0]

    def record():
        sock.settimeout(0.2)
        with open(args.record, "w") as out:
            while not stop.is_set():
                try:
                    raw = sock.recv(72)
                except socket.timeout:
                    continue
                # The shim appends when the daemon sent it (CLOCK_MONOTONIC ns).
                t = struct.unpack_from("<q", raw, len(raw) - 8)[0] * 1e-9
                can_id, n = struct.unpack_from("<IB", raw)
                ident = can_id & (0x1FFFFFFF if can_id & CAN_EFF_FLAG else 0x7FF)
                out.write(f"{t:.6f} {ident:X} {n} {raw[8:8 + n].hex()}\n")
                received[0] += 1

    reader = threading.Thread(target=record)
    reader.start()
    sent = 0
    end = time.monotonic() + args.duration
    frames = read_candump(args.replay) if args.replay else []
    if frames:
        span = frames[-1][0] - frames[0][0] + 0.01
        start = time.monotonic()
        lap = 0
        while not stop.is_set() and time.monotonic() < end:
            for t, can_id, data in frames:
                due = start + lap * span + (t - frames[0][0])
                wait = due - time.monotonic()
                if wait > 0.002:
                    if stop.wait(wait):
                        break
                if time.monotonic() >= end:
                    break
                try:
                    sock.sendto(frame_bytes(can_id, data), gw_path)
                    sent += 1
                except (FileNotFoundError, ConnectionRefusedError, BlockingIOError):
                    pass  # the daemon is not (yet, or any more) listening
            else:
                lap += 1
                continue
            break
    while not stop.is_set() and time.monotonic() < end:
        stop.wait(0.1)
    stop.set()
    reader.join()
    print(f"can_bus: {sent} frames sent to the daemon, {received[0]} received from it")


if __name__ == "__main__":
    main()
