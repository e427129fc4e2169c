#!/usr/bin/python3
"""A site of pumps publishing over MQTT, simulated on this machine (docs/site.md): a measurement,
not a test (it prints figures, it never fails on them).

One local mosquitto (plain text, loopback, the per-client limits docs/site.md recommends), N
gateway processes, each `pumpthermd -r RECORDING --pace 1` (real time) with 25 pumps (13 on can0,
12 on can1: the mapping allows node IDs 0..15 per bus) of the plant's fleet32 recording and its
own edge node id, started 1/N s apart so that their thermal steps do not all fall in the same
millisecond; and a subscriber (paho, in this process) that counts the messages and measures, for
each DDATA, its arrival (wall clock) minus the step's timestamp.

The gateways replay the same recording, so a step's timestamp is the recording's time: the delay
is reported above each gateway's fastest message (arrival - timestamp - min over that gateway),
which removes the gateway's start offset and is the frame-to-MQTT delay less that gateway's
smallest one (sub-millisecond on loopback).

CPU from /proc/PID/stat (utime + stime), sampled between WARM s after the start and the end of
the replay, for the broker, each gateway and this subscriber; the load average from /proc/loadavg.

  mqtt_site.py --pumpthermd build/daemon/pumpthermd --pumptherm build/tools/pumptherm \
      --source . --gateways 2 --duration-s 90 [--work /tmp/site]
"""
import argparse
import json
import os
import socket
import subprocess
import sys
import threading
import time

import paho.mqtt.client as mqtt

TICK = os.sysconf("SC_CLK_TCK")


def cpu_s(pid):
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICK  # utime, stime (fields 14, 15)


def free_port():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def percentile(v, q):
    if not v:
        return float("nan")
    v = sorted(v)
    return v[min(len(v) - 1, int(q * (len(v) - 1)))]


def recording(a):
    """The fleet32 recording, cut to --duration-s and to 13 pumps on can0, 12 on can1."""
    fleet = os.path.join(a.work, "fleet")
    if not os.path.exists(os.path.join(fleet, "fleet32.log")):
        subprocess.run([a.pumptherm, "plant", "fleet32", "--duration-s", str(a.duration_s + 5),
                        "--out", fleet, "--quiet"], check=True)
    log = os.path.join(a.work, f"site-{a.duration_s:.0f}.log")
    if not os.path.exists(log):
        with open(os.path.join(fleet, "fleet32.log")) as f, open(log, "w") as out:
            first = None
            for line in f:
                t = float(line[1:line.index(")")])
                first = t if first is None else first
                if t - first >= a.duration_s:
                    break
                iface, frame = line.split()[1:3]
                node = int(frame[2], 16)
                if node < (13 if iface == "can0" else 12):
                    out.write(line)
    return log


def pumps_config(source):
    """[[can]] and the 25 [[pump]] tables (fleet32_pumps.sh, a00..a12 and b00..b11)."""
    text = subprocess.run(["sh", os.path.join(source, "tests/data/fleet32_pumps.sh")],
                          check=True, capture_output=True, text=True).stdout
    blocks = text.split("\n[[pump]]\n")
    keep = [blocks[0]]
    for b in blocks[1:]:
        name = b.split('"')[1]
        if int(name[1:]) < (13 if name[0] == "a" else 12):
            keep.append(b)
    return "\n[[pump]]\n".join(keep)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--pumpthermd", required=True)
    ap.add_argument("--pumptherm", required=True)
    ap.add_argument("--source", required=True)
    ap.add_argument("--gateways", type=int, required=True)
    ap.add_argument("--duration-s", type=float, default=90.0)
    ap.add_argument("--warm-s", type=float, default=10.0)
    ap.add_argument("--work", default="/tmp/pumptherm-site")
    ap.add_argument("--dump", help="write each DDATA's (gateway, pump, timestamp_ms, arrival_s)")
    a = ap.parse_args()
    os.makedirs(a.work, exist_ok=True)
    log = recording(a)
    run = os.path.join(a.work, f"run-{a.gateways}")
    os.makedirs(run, exist_ok=True)
    subprocess.run(["protoc", f"--python_out={run}", "-I", os.path.join(a.source, "protocol"),
                    os.path.join(a.source, "protocol/sparkplug_b.proto")], check=True)
    sys.path.insert(0, run)
    import sparkplug_b_pb2 as spb

    port = free_port()
    with open(os.path.join(run, "mosquitto.conf"), "w") as f:
        f.write(f"user {os.environ.get('USER', 'root')}\nlog_dest file {run}/mosquitto.log\n"
                f"listener {port} 127.0.0.1\nallow_anonymous true\n"
                "max_inflight_messages 20\nmax_queued_messages 1000\n")
    broker = subprocess.Popen(["mosquitto", "-c", os.path.join(run, "mosquitto.conf")],
                              stderr=subprocess.DEVNULL)
    for _ in range(100):
        try:
            socket.create_connection(("127.0.0.1", port), 0.2).close()
            break
        except OSError:
            time.sleep(0.1)

    lock = threading.Lock()
    seen = {"msgs": 0, "ddata": 0, "births": 0, "deaths": 0, "bytes": 0}
    delays = {}  # edge node -> [arrival - timestamp, s]
    dump = []

    def on_message(client, userdata, msg):
        now = time.time()
        parts = msg.topic.split("/")
        with lock:
            seen["msgs"] += 1
            seen["bytes"] += len(msg.payload)
            if parts[2] == "DDATA":
                p = spb.Payload()
                p.ParseFromString(msg.payload)
                seen["ddata"] += 1
                delays.setdefault(parts[3], []).append(now - p.timestamp / 1000.0)
                if a.dump:
                    dump.append((parts[3], parts[4], p.timestamp, now))
            elif parts[2] in ("NBIRTH", "DBIRTH"):
                seen["births"] += 1
            elif parts[2] == "NDEATH":
                seen["deaths"] += 1

    sub = mqtt.Client(client_id="site-historian")
    sub.on_message = on_message
    sub.on_connect = lambda c, u, f, rc: c.subscribe("spBv1.0/#", qos=1)
    sub.connect("127.0.0.1", port, keepalive=30)
    sub.loop_start()
    time.sleep(0.5)

    pumps = pumps_config(a.source)
    gws = []
    start = time.time()
    for i in range(a.gateways):
        cfg = os.path.join(run, f"gw{i:02d}.toml")
        with open(cfg, "w") as f:
            f.write(f'[gateway]\nname = "gw{i:02d}"\nheartbeat_period_s = 0\n\n[alarms.levels]\n'
                    'winding = { warning_degC = 100.0, trip_degC = 120.0 }\n\n')
            f.write(pumps)
            f.write(f'\n[mqtt]\nhost = "127.0.0.1"\nport = {port}\ngroup_id = "site"\n'
                    f'edge_node_id = "gw{i:02d}"\n')
        out = open(os.path.join(run, f"gw{i:02d}.out"), "w")
        err = open(os.path.join(run, f"gw{i:02d}.err"), "w")
        gws.append(subprocess.Popen([a.pumpthermd, "--config", cfg, "-r", log, "--pace", "1"],
                                    stdout=out, stderr=err, env=dict(os.environ, TZ="UTC")))
        time.sleep(1.0 / a.gateways)

    time.sleep(a.warm_s)
    me = os.getpid()
    pids = {"broker": broker.pid, "subscriber": me, **{f"gw{i:02d}": g.pid for i, g in enumerate(gws)}}
    c0 = {k: cpu_s(p) for k, p in pids.items()}
    with lock:
        m0 = dict(seen)
    t0 = time.time()
    load = []
    while all(g.poll() is None for g in gws):
        with open("/proc/loadavg") as f:
            load.append(float(f.read().split()[0]))
        last = {}
        for k, p in pids.items():
            try:
                last[k] = cpu_s(p)
            except OSError:
                pass
        c1, t1 = last, time.time()
        with lock:
            m1 = dict(seen)
        time.sleep(1.0)
    walls = []
    for g in gws:
        g.wait()
        walls.append(time.time() - start)
    time.sleep(1.0)
    sub.loop_stop()
    broker.terminate()
    broker.wait()

    window = t1 - t0
    gw_cpu = [(c1[k] - c0[k]) / window for k in pids if k.startswith("gw") and k in c1]
    dropped = 0
    for i in range(a.gateways):
        for line in open(os.path.join(run, f"gw{i:02d}.out")):
            if line.startswith("mqtt "):
                dropped += int(line.split(" dropped,")[0].rsplit(", ", 1)[1])
    rel = []
    for node, d in delays.items():
        base = min(d)
        rel += [x - base for x in d]
    steps_expected = a.gateways * 25 * a.duration_s
    result = {
        "gateways": a.gateways, "pumps": a.gateways * 25, "duration_s": a.duration_s,
        "window_s": round(window, 1),
        "msgs_per_s": round((m1["msgs"] - m0["msgs"]) / window, 1),
        "ddata_per_s": round((m1["ddata"] - m0["ddata"]) / window, 1),
        "bytes_per_s": round((m1["bytes"] - m0["bytes"]) / window),
        "ddata_total": seen["ddata"], "births": seen["births"], "deaths": seen["deaths"],
        "steps_expected_approx": int(steps_expected),
        "sink_dropped_total": dropped,
        "broker_cpu_pct": round(100 * (c1["broker"] - c0["broker"]) / window, 1),
        "gateway_cpu_pct_mean": round(100 * sum(gw_cpu) / max(1, len(gw_cpu)), 2),
        "gateway_cpu_pct_max": round(100 * max(gw_cpu or [0]), 2),
        "gateways_cpu_pct_sum": round(100 * sum(gw_cpu), 1),
        "subscriber_cpu_pct": round(100 * (c1["subscriber"] - c0["subscriber"]) / window, 1),
        "delay_ms_p50": round(1000 * percentile(rel, 0.5), 1),
        "delay_ms_p99": round(1000 * percentile(rel, 0.99), 1),
        "delay_ms_max": round(1000 * max(rel or [float("nan")]), 1),
        "gateway_wall_s_max": round(max(walls) - (a.gateways - 1) / a.gateways, 1),
        "load_avg_1min_mean": round(sum(load) / max(1, len(load)), 2),
        "load_avg_1min_max": max(load or [0]),
    }
    print(json.dumps(result))
    if a.dump:
        with open(a.dump, "w") as f:
            json.dump(dump, f)
    return 0


if __name__ == "__main__":
    sys.exit(main())
