#!/bin/sh
# The full-bus load of daemon_full_bus.sh (40 s at 9000 frames/s, 16 pumps) with the bus recorded
# by candump in the guest and the daemon's CPU share over the playback; the capture comes back to
# the host (--out-dir) for tests/bench/reaction_latency.py: the delay from the telemetry frame
# that completes a pump's thermal period to its GW_NODE_TEMP and GW_ALARM frames
# (docs/robustness.md, "Live reaction").
set -eu
SCENARIO_NAME=daemon_full_bus_latency
LATENCY=1
. "$DATA_DIR/daemon_full_bus.sh"
