#!/bin/sh
# Vcan test (c): the daemon survives `ip link set vcan0 down` and `up` and counts again
# afterwards; it also survives vcan0 being deleted and re-created (it reopens the socket).
set -eu
SCENARIO_NAME=daemon_link_down_up
. "$DATA_DIR/daemon_lib.sh"

cat >"$WORK_DIR/pumpthermd.toml" <<TOML
[gateway]
heartbeat_period_s = 0.2

[[can]]
interface = "vcan0"
TOML
send_n() {  # send_n FRAME N
  i=0
  while [ "$i" -lt "$2" ]; do cansend vcan0 "$1" || fail "cansend $1"; i=$((i + 1)); done
}
wait_log() {  # wait_log PATTERN
  tries=0
  until grep -q "$1" "$WORK_DIR/daemon.err"; do
    tries=$((tries + 1)); [ "$tries" -le 50 ] || fail "the daemon never logged '$1'"; sleep 0.2
  done
}

start_daemon "$WORK_DIR/pumpthermd.toml"
send_n 123#01 5
ip link set vcan0 down
wait_log "vcan0: interface is down"
if cansend vcan0 123#99 2>/dev/null; then fail "cansend worked on a down interface"; fi
sleep 1
ip link set vcan0 up
wait_log "vcan0: interface is up again"
send_n 124#02 7
kill -0 "$DAEMON_PID" || fail "daemon died across down/up"

ip link del dev vcan0
wait_log "vcan0: interface was removed"
sleep 1
ip link add dev vcan0 type vcan
ip link set vcan0 up
wait_log "vcan0: interface is back; socket reopened"
send_n 125#03 9
sleep 0.5
stop_daemon

c123=$(count_of 123); c124=$(count_of 124); c125=$(count_of 125)
echo "daemon_link_down_up: counts 123=$c123 (before down) 124=$c124 (after up) 125=$c125 (after re-create)"
[ "$c123" -eq 5 ] || fail "123: $c123 frames, want 5"
[ "$c124" -eq 7 ] || fail "124: $c124 frames, want 7"
[ "$c125" -eq 9 ] || fail "125: $c125 frames, want 9"
echo "daemon_link_down_up: PASS"
