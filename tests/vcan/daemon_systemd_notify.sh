#!/bin/sh
# The daemon's side of the systemd notify protocol, seen by a listener on
# NOTIFY_SOCKET: READY=1 once the socket is bound, STATUS= with the counts, WATCHDOG=1 at
# least every half WatchdogSec, STOPPING=1 on SIGTERM.
set -eu
SCENARIO_NAME=daemon_systemd_notify
. "$DATA_DIR/daemon_lib.sh"

cat >"$WORK_DIR/pumpthermd.toml" <<TOML
[gateway]
status_period_s = 0.5

[[can]]
interface = "vcan0"
TOML
sock=$WORK_DIR/notify.sock
"$BIN_DIR/notify_listener" "$sock" 30 >"$WORK_DIR/notify.txt" &
LISTENER_PID=$!
tries=0
until [ -S "$sock" ]; do tries=$((tries + 1)); [ "$tries" -le 50 ] || fail "listener did not start"; sleep 0.1; done

start_daemon "$WORK_DIR/pumpthermd.toml" NOTIFY_SOCKET="$sock" WATCHDOG_USEC=400000
cansend vcan0 181#0011223344556677   # right after READY: must be counted
sleep 3
stop_daemon
sleep 0.3
kill "$LISTENER_PID" 2>/dev/null || true
wait "$LISTENER_PID" 2>/dev/null || true

echo "daemon_systemd_notify: messages received:"
sed 's/^/  /' "$WORK_DIR/notify.txt" | head -n 12
head -n 1 "$WORK_DIR/notify.txt" | grep -q "READY=1" || fail "first message is not READY=1"
tail -n 1 "$WORK_DIR/notify.txt" | grep -q "STOPPING=1" || fail "last message is not STOPPING=1"
wd=$(grep -c "^WATCHDOG=1$" "$WORK_DIR/notify.txt" || true)
# 3 s with WatchdogSec 0.4 s: a kick every 0.2 s, about 15.
[ "$wd" -ge 10 ] || fail "only $wd WATCHDOG=1 in 3 s (want >= 10)"
grep -q "^STATUS=.*rx 1 frames, 1 IDs" "$WORK_DIR/notify.txt" || fail "no STATUS line counting the frame"
[ "$(count_of 181)" -eq 1 ] || fail "the frame sent right after READY was not counted"
echo "daemon_systemd_notify: PASS ($wd watchdog kicks)"
