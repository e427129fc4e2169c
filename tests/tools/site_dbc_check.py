#!/usr/bin/python3
"""Decodes the gateway's CAN output with a site DBC (`pumptherm dbc export`) in Debian's
python3-canmatrix, an independent DBC reader, for tests/tools/dbc_export_test.sh.

    /usr/bin/python3 site_dbc_check.py SITE.dbc NAMED.dbc GATEWAY.log PUMP...

SITE.dbc is the default export, NAMED.dbc the one with --node-signals, GATEWAY.log the candump
log `pumpthermd -r --output-log` wrote, PUMP... the configured pump names. Checks: every frame
has a message, named MESSAGE_PUMP (long names as canmatrix reads them); each pump's
GW_NODE_TEMP names its model's nodes by NodeIndex; some GW_ALARM names the winding by AlarmNode;
the heartbeat's uptime counts the seconds; NAMED.dbc's winding_degC is the NodeTemp_degC of the
same frame. Prints what it found; exit 1 on the first thing that is wrong.
"""
import io
import logging
import sys
from collections import Counter


def load(path):
    import canmatrix.formats
    logging.disable(logging.CRITICAL)  # canmatrix logs and prints what it cannot read
    stdout, sys.stdout = sys.stdout, io.StringIO()
    try:
        return canmatrix.formats.loadp_flat(path)
    finally:
        sys.stdout = stdout


def quietly_import():
    # canmatrix names on stderr the formats whose Python modules Debian does not ship.
    stderr, sys.stderr = sys.stderr, io.StringIO()
    try:
        import canmatrix.formats  # noqa: F401
    finally:
        sys.stderr = stderr


def frames(log_path):
    import canmatrix
    with open(log_path) as log:
        for line in log:
            stamp, iface, frame = line.split()[:3]
            ident, data = frame.split("#")
            arb = canmatrix.ArbitrationId(id=int(ident, 16), extended=len(ident) == 8)
            yield float(stamp.strip("()")), arb, bytearray.fromhex(data)


def fail(what):
    print("site_dbc_check: FAIL: " + what)
    sys.exit(1)


def main():
    site_path, named_path, log_path, pumps = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4:]
    quietly_import()
    site, named = load(site_path), load(named_path)
    messages, node_names, alarm_nodes = Counter(), {}, Counter()
    uptimes, same = [], 0
    for stamp, arb, data in frames(log_path):
        frame = site.frame_by_id(arb)
        if frame is None:
            fail("no message for ID 0x%X in %s" % (arb.id, site_path))
        decoded = frame.decode(data)
        messages[frame.name] += 1
        if frame.name.startswith("GW_NODE_TEMP_"):
            pump = frame.name[len("GW_NODE_TEMP_"):]
            node_names.setdefault(pump, set()).add(decoded["NodeIndex"].named_value)
            # The named export: winding_degC (etc.) is this frame's NodeTemp_degC.
            other = named.frame_by_id(arb).decode(data)
            node = decoded["NodeIndex"].named_value
            if node + "_degC" not in other:
                fail("%s: no signal %s_degC in %s" % (frame.name, node, named_path))
            if other[node + "_degC"].raw_value != decoded["NodeTemp_degC"].raw_value:
                fail("%s: %s_degC differs from NodeTemp_degC" % (frame.name, node))
            same += 1
        if frame.name.startswith("GW_ALARM_"):
            alarm_nodes[decoded["AlarmNode"].named_value] += 1
        if frame.name == "GW_HEARTBEAT":
            uptimes.append((stamp, decoded["Uptime_s"].raw_value))
    for pump in pumps:
        for message in ("GW_NODE_TEMP", "GW_ALARM", "GW_TEMPS_A", "GW_HEALTH"):
            if messages[message + "_" + pump] == 0:
                fail("no %s_%s frame decoded" % (message, pump))
        if node_names.get(pump) != {"frame", "stator", "winding", "rotor"}:
            fail("%s: NodeIndex names %s" % (pump, sorted(node_names.get(pump, []))))
    if alarm_nodes["winding"] == 0:
        fail("no GW_ALARM names the winding by AlarmNode: %s" % dict(alarm_nodes))
    if len(uptimes) < 10 or any(abs(u - (s - uptimes[0][0])) >= 1 for s, u in uptimes):
        fail("the heartbeat's Uptime_s does not count the seconds: %s" % uptimes[:5])
    print("site_dbc_check: %d frames, %d messages decoded by canmatrix; NodeIndex names %s; "
          "AlarmNode %s; %d heartbeats; %d named node temperatures equal NodeTemp_degC"
          % (sum(messages.values()), len(messages), sorted(node_names[pumps[0]]),
             dict(alarm_nodes), len(uptimes), same))


main()
