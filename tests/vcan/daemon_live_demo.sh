#!/bin/sh
# Vcan: the README demo's live flag. tools/demo-live.sh (what `tools/demo.sh
# --live` runs after simulating) is run unchanged from a source-tree layout staged in the guest
# (tools/, build/daemon/pumpthermd, the shipped files under build/share/pumptherm where the
# daemon's resolver finds them next to its binary), on the first 30 s of the plant's demo
# recording. Checks: it exits 0; pumpthermd received every replayed frame (or counted it as a
# receive-queue drop); it printed its pump table while running; the gateway's frames for the
# three pumps were captured; an LCM subscriber (lcm-logger) on the guest's loopback received
# every pump's TELEMETRY, TEMPS and ALARM and the gateway's HEALTH.
# Then the offline LCM log of the same recording (pumpthermd -r --lcm-log)
# played by lcm-logplayer reaches an lcm-logger with every message of the file.
set -eu
SCENARIO_NAME=daemon_live_demo
. "$DATA_DIR/daemon_lib.sh"

tree=$WORK_DIR/tree
mkdir -p "$tree/tools/demo" "$tree/build/daemon" "$tree/build/share/pumptherm/dbc" \
  "$tree/build/share/pumptherm/models" "$tree/build/share/pumptherm/motors" "$tree/demo-out"
cp "$DATA_DIR/demo-live.sh" "$tree/tools/"
cp "$DATA_DIR/pumpthermd-demo.toml" "$tree/tools/demo/"
cp "$BIN_DIR/pumpthermd" "$tree/build/daemon/"
cp "$DATA_DIR/pumptherm.dbc" "$DATA_DIR/mapping_pumptherm.toml" "$tree/build/share/pumptherm/dbc/"
cp "$DATA_DIR/tmp-generic.toml" "$tree/build/share/pumptherm/models/"
cp "$DATA_DIR/han2019-tmp.toml" "$tree/build/share/pumptherm/motors/"
chmod +x "$tree/tools/demo-live.sh" "$tree/build/daemon/pumpthermd"
# The first 30 s of the recording, as tools/demo.sh writes it (interface can0).
awk 'NR == 1 { t0 = substr($1, 2) + 0 } substr($1, 2) + 0 - t0 < 30' "$DATA_DIR/pipeline.log" >"$tree/demo-out/demo.log"
n_log=$(wc -l <"$tree/demo-out/demo.log")
echo "$SCENARIO_NAME: recording: $n_log frames (30 s of three pumps)"

lcm-logger --quiet "$WORK_DIR/live.lcm" >/dev/null 2>&1 &
LOGGER_PID=$!
sleep 0.5
rc=0
(cd "$tree" && tools/demo-live.sh demo-out) >"$WORK_DIR/demo.out" 2>"$WORK_DIR/demo.err" || rc=$?
sleep 0.3
kill "$LOGGER_PID" 2>/dev/null || true
wait "$LOGGER_PID" 2>/dev/null || true
sed 's/^/  stdout| /' "$WORK_DIR/demo.out"
[ "$rc" -eq 0 ] || { sed 's/^/  stderr| /' "$WORK_DIR/demo.err"; fail "tools/demo-live.sh exited with $rc"; }

status=$(head -n 1 "$tree/demo-out/pumpthermd-live.txt")
echo "$SCENARIO_NAME: gateway: $status"
rx=$(echo "$status" | sed -n 's/^.*rx \([0-9]*\) frames.*$/\1/p')
rx_drops=$(echo "$status" | sed -n 's/^.*, \([0-9]*\) rx drops.*$/\1/p')
# Drop accounting is daemon_pipeline_outage's job (it sends a marker frame after its replay so
# that tail drops are reported); here the demo must simply have run on the replayed traffic.
[ $((rx + rx_drops)) -le "$n_log" ] || fail "the daemon received $rx (+ $rx_drops drops), more than the $n_log replayed"
[ $((rx * 100)) -ge $((n_log * 95)) ] || fail "the daemon received only $rx of the $n_log replayed frames"

tables=$(grep -c '^pump3 ' "$WORK_DIR/demo.err" || true)
echo "$SCENARIO_NAME: pump tables printed while running: $tables"
[ "$tables" -ge 4 ] || { sed 's/^/  stderr| /' "$WORK_DIR/demo.err"; fail "expected a pump table every 5 s (30 s run), saw $tables"; }
grep -q "demo-live: done" "$WORK_DIR/demo.out" || fail "demo-live.sh did not finish its run"

out_log=$tree/demo-out/gateway-live.log
for node in 1 2 3; do
  for base in 200 400 410 420 600; do  # GW_ALARM, GW_TEMPS_A, GW_TEMPS_B, GW_IDENT, GW_HEALTH
    id=$(printf '%03X' $((0x$base + node)))
    n=$(grep -c " $id#" "$out_log" || true)
    [ "$n" -gt 0 ] || fail "no frame $id from the gateway in $out_log"
  done
done
echo "$SCENARIO_NAME: gateway frames captured: $(wc -l <"$out_log")"

strings "$WORK_DIR/live.lcm" | grep -oE 'PUMPTHERM/[A-Za-z0-9_.-]*/(TELEMETRY|TEMPS|ALARM_CLEAR_REPLY|ALARM|HEALTH|DIGEST)' | sort | uniq -c >"$WORK_DIR/channels.txt" || true
echo "$SCENARIO_NAME: LCM channels received live:"
sed 's/^/  /' "$WORK_DIR/channels.txt"
for p in pump1 pump2 pump3; do
  for kind in TELEMETRY TEMPS ALARM; do
    grep -q " PUMPTHERM/$p/$kind\$" "$WORK_DIR/channels.txt" || fail "no PUMPTHERM/$p/$kind message reached the LCM subscriber"
  done
done
grep -q " PUMPTHERM/GATEWAY/HEALTH\$" "$WORK_DIR/channels.txt" || fail "no PUMPTHERM/GATEWAY/HEALTH message"

# lcm-logplayer plays the offline LCM log (pumpthermd -r --lcm-log) to a subscriber.
"$tree/build/daemon/pumpthermd" --config "$tree/tools/demo/pumpthermd-demo.toml" -r "$tree/demo-out/demo.log" \
  --lcm-log "$WORK_DIR/offline.lcm" >"$WORK_DIR/offline.txt" 2>"$WORK_DIR/offline.err" || fail "offline run failed"
n_offline=$(sed -n 's/^sent [0-9]* frames and \([0-9]*\) LCM messages.*$/\1/p' "$WORK_DIR/offline.txt")
# Events in an LCM log file, counted by their channel names (plain text in each event).
events() { strings "$1" | grep -o 'PUMPTHERM/' | wc -l; }
n_file=$(events "$WORK_DIR/offline.lcm")
lcm-logger --quiet "$WORK_DIR/played.lcm" >/dev/null 2>&1 &
LOGGER_PID=$!
sleep 0.5
lcm-logplayer --speed 10 "$WORK_DIR/offline.lcm" >"$WORK_DIR/player.out" 2>&1 || fail "lcm-logplayer failed: $(cat "$WORK_DIR/player.out")"
sleep 0.5
kill "$LOGGER_PID" 2>/dev/null || true
wait "$LOGGER_PID" 2>/dev/null || true
n_played=$(events "$WORK_DIR/played.lcm")
echo "$SCENARIO_NAME: offline LCM log: $n_offline messages written, $n_file events in the file; lcm-logplayer -> lcm-logger: $n_played received"
[ -n "$n_offline" ] && [ "$n_offline" -gt 100 ] || fail "the offline run wrote no LCM messages ($n_offline)"
[ "$n_file" -eq "$n_offline" ] || fail "the LCM log holds $n_file events, the daemon wrote $n_offline"
[ "$n_played" -eq "$n_offline" ] || fail "lcm-logplayer delivered $n_played of the $n_offline messages in the file"
echo "$SCENARIO_NAME: PASS"
