#!/bin/sh
# Vcan test (b): candump on vcan0 sees the daemon's heartbeat frames at the configured
# rate (10 Hz here), with an uptime that advances.
set -eu
SCENARIO_NAME=daemon_heartbeat
. "$DATA_DIR/daemon_lib.sh"

cat >"$WORK_DIR/pumpthermd.toml" <<TOML
[gateway]
heartbeat_id = 0x7F0
heartbeat_period_s = 0.1

[[can]]
interface = "vcan0"
TOML
candump -L vcan0,7F0:7FF >"$WORK_DIR/hb.log" &
CANDUMP_PID=$!
sleep 0.5
start_daemon "$WORK_DIR/pumpthermd.toml"
sleep 6
stop_daemon
sleep 0.2
kill "$CANDUMP_PID" 2>/dev/null || true
wait "$CANDUMP_PID" 2>/dev/null || true

n=$(grep -c " vcan0 7F0#" "$WORK_DIR/hb.log" || true)
[ "$n" -ge 40 ] || fail "only $n heartbeat frames in about 6 s"
# Rate over the captured span, from candump's kernel timestamps.
rate=$(awk '{ t = substr($1, 2, length($1) - 2); if (NR == 1) t0 = t; t1 = t } END { printf "%.3f", (NR - 1) / (t1 - t0) }' "$WORK_DIR/hb.log")
echo "daemon_heartbeat: $n frames, $rate Hz (configured 10 Hz)"
awk -v r="$rate" 'BEGIN { exit !(r > 9.5 && r < 10.5) }' || fail "heartbeat rate $rate Hz is not 10 Hz +/- 5 %"
# Payload bytes 0-3: uptime in s, little endian; it must reach at least 5 s.
last=$(tail -n 1 "$WORK_DIR/hb.log" | sed 's/.*#//')
uptime=$(printf '%d' "0x$(echo "$last" | cut -c7-8)$(echo "$last" | cut -c5-6)$(echo "$last" | cut -c3-4)$(echo "$last" | cut -c1-2)")
[ "$uptime" -ge 5 ] || fail "uptime in the last heartbeat is $uptime s, want >= 5"
grep -q "tx $n frames" "$WORK_DIR/daemon.out" || fail "the daemon's tx count differs from candump's $n"
echo "daemon_heartbeat: PASS (last uptime $uptime s, daemon tx count = candump count)"
