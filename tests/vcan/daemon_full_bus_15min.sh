#!/bin/sh
# The live load of daemon_full_bus.sh for 15 minutes and 20 s (the 40 s
# full-bus recording played 23 times by canplayer -l), zero receive drops, every frame received,
# and the bus at a full 1 Mbit/s bus's rate on average. A measurement (label "measurement"), not
# in CI; its cost is in docs/robustness.md, "Soak".
#   ctest --test-dir build -R vcan.daemon_full_bus_15min -V
SCENARIO_NAME=daemon_full_bus_15min
FULL_BUS_LOOPS=23
. "$DATA_DIR/daemon_full_bus.sh"
