#!/bin/sh
# Vcan test (a): canplayer replays the bundled candump log onto vcan0 and the daemon's
# per-ID counts match the log exactly, and match the daemon's own offline run of the same log.
set -eu
SCENARIO_NAME=daemon_replay
. "$DATA_DIR/daemon_lib.sh"

cat >"$WORK_DIR/pumpthermd.toml" <<TOML
[gateway]
heartbeat_period_s = 1.0

[[can]]
interface = "vcan0"
TOML
start_daemon "$WORK_DIR/pumpthermd.toml"
# Original timing (10 s of traffic), the log's can0 mapped onto vcan0.
canplayer -I "$DATA_DIR/skeleton.log" vcan0=can0 || fail "canplayer failed"
sleep 0.5
stop_daemon

awk '{ split($3, a, "#"); n[a[1]]++ } END { for (k in n) print k, n[k] }' "$DATA_DIR/skeleton.log" \
  | sort >"$WORK_DIR/want.txt"
awk '$1 == "vcan0" { print $2, $3 }' "$WORK_DIR/daemon.out" | sort >"$WORK_DIR/live.txt"
"$BIN_DIR/pumpthermd" -r "$DATA_DIR/skeleton.log" | awk 'NR > 2 { print $2, $3 }' | sort >"$WORK_DIR/offline.txt"
echo "daemon_replay: log / live / offline per-ID counts:"
paste "$WORK_DIR/want.txt" "$WORK_DIR/live.txt" "$WORK_DIR/offline.txt" | sed 's/^/  /'
cmp -s "$WORK_DIR/want.txt" "$WORK_DIR/live.txt" || fail "live counts differ from the log"
cmp -s "$WORK_DIR/want.txt" "$WORK_DIR/offline.txt" || fail "offline counts differ from the log"
grep -q " 0 rx drops" "$WORK_DIR/daemon.out" || fail "receive drops reported"
echo "daemon_replay: PASS: $(awk '{ s += $2 } END { print s }' "$WORK_DIR/want.txt") frames, live = offline = log"
