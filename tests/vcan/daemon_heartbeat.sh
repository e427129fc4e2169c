#!/bin/sh
# Vcan test (b): candump on vcan0 sees the daemon's heartbeat frames at the configured
# rate (10 Hz here), with an uptime that advances. Then (guest only: natively the host's clock is
# not ours to set) the wall clock stepped back 200 s and forward again while one pump's recording
# is replayed (docs/daemon.md, "Time"): heartbeat, temperature and alarm frames keep coming in
# every phase, and the trip latches where the offline run of the same recording latches it.
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
echo "daemon_heartbeat: heartbeat PASS (last uptime $uptime s, daemon tx count = candump count)"

if [ "$VCAN_MODE" != guest ]; then
  echo "daemon_heartbeat: clock steps skipped: $VCAN_MODE mode would set the host's clock"
  exit 0
fi
cat >"$WORK_DIR/clock.toml" <<TOML
[gateway]
heartbeat_id = 0x7F0
heartbeat_period_s = 0.1
thermal_period_s = 1.0

[dbc]
file = "$DATA_DIR/pumptherm.dbc"
mapping = "$DATA_DIR/mapping_pumptherm.toml"

[alarms]
hold_s = 2.0
stale_after_s = 2.0
[alarms.levels]
winding = { warning_degC = 100.0, trip_degC = 120.0 }

[[can]]
interface = "vcan0"

[[pump]]
name = "pump1"
node_id = 1
motor = "$DATA_DIR/han2019-tmp.toml"
thermal_model = "$DATA_DIR/tmp-generic.toml"
frame_sensor_lag_s = 30.0
TOML
"$BIN_DIR/pumpthermd" --check-config "$WORK_DIR/clock.toml" || fail "the clock-step configuration is invalid"
# part FROM TO: the recording's frames with FROM <= t - t0 < TO, on vcan0. Each part is its own
# canplayer run: canplayer paces on the wall clock, so a step must fall between two runs.
part() {
  awk -v a="$1" -v b="$2" 'NR == 1 { t0 = substr($1, 2) + 0 }
    { t = substr($1, 2) + 0 - t0 } t >= a && t < b { sub(/ can0 /, " vcan0 "); print }' "$DATA_DIR/clock-step.log"
}
part 0 45 >"$WORK_DIR/clock_whole.log"
# The offline run of the same frames: when the trip latches (the first GW_ALARM, 0x201, at level 2).
"$BIN_DIR/pumpthermd" --config "$WORK_DIR/clock.toml" -r "$WORK_DIR/clock_whole.log" \
  --output-log "$WORK_DIR/clock_offline.log" >/dev/null 2>"$WORK_DIR/clock_offline.err" || fail "offline run failed"
t0=$(head -n 1 "$WORK_DIR/clock_whole.log" | sed 's/^(\([0-9.]*\)).*/\1/')
trip_off=$(awk -v t0="$t0" '{ split($3, f, "#") } f[1] == "201" && substr(f[2], 2, 1) ~ /[26AE]/ {
  printf "%.1f", substr($1, 2, length($1) - 2) - t0; exit }' "$WORK_DIR/clock_offline.log")
[ -n "$trip_off" ] || fail "the offline run of the clock-step recording never trips"

candump -r 8388608 -L vcan0 >"$WORK_DIR/clock_bus.log" &
CANDUMP_PID=$!
sleep 0.5
start_daemon "$WORK_DIR/clock.toml"
wall0=$(date +%s)
# Phases, each ended by a marker frame (7FE#0N, an ID no pump uses): 0-15 s; the clock set back
# 200 s, 15-30 s; the clock set forward 200 s, 30-45 s.
part 0 15 >"$WORK_DIR/p1.log"; part 15 30 >"$WORK_DIR/p2.log"; part 30 45 >"$WORK_DIR/p3.log"
canplayer -I "$WORK_DIR/p1.log" || fail "canplayer (phase 1) failed"
cansend vcan0 7FE#01
date -s "@$(($(date +%s) - 200))" >/dev/null || fail "date -s (back) failed"
canplayer -I "$WORK_DIR/p2.log" || fail "canplayer (phase 2) failed"
cansend vcan0 7FE#02
date -s "@$(($(date +%s) + 200))" >/dev/null || fail "date -s (forward) failed"
canplayer -I "$WORK_DIR/p3.log" || fail "canplayer (phase 3) failed"
cansend vcan0 7FE#03
sleep 1
wall1=$(date +%s)
stop_daemon
sleep 0.2
kill "$CANDUMP_PID" 2>/dev/null || true
wait "$CANDUMP_PID" 2>/dev/null || true
echo "daemon_heartbeat: clock steps: replay of 45 s took $((wall1 - wall0)) s of wall clock (stepped back and forward 200 s)"

# Frames of ID $1 in each phase (between the markers), as "n1 n2 n3".
per_phase() {
  awk -v id="$1" 'BEGIN { p = 0 } { split($3, f, "#") } f[1] == "7FE" { p++ } f[1] == id && p < 3 { n[p]++ }
    END { printf "%d %d %d", n[0], n[1], n[2] }' "$WORK_DIR/clock_bus.log"
}
# Each phase lasts 15 s: at least 80 % of the frames due (heartbeat 10 Hz, GW_TEMPS_A
# at its DBC cycle of 1 s, GW_ALARM of 0.1 s). A clock set back stopped them for 200 s when elapsed
# time was wall time.
for spec in "7F0 10" "401 1" "201 10"; do
  id=${spec% *}; hz=${spec#* }
  counts=$(per_phase "$id")
  echo "daemon_heartbeat: clock steps: $id frames per phase (15 s, back 200 s then 15 s, forward 200 s then 15 s): $counts"
  set -- $counts
  [ "$1" -ge $((12 * hz)) ] && [ "$2" -ge $((12 * hz)) ] && [ "$3" -ge $((12 * hz)) ] ||
    fail "$id: too few frames in a phase ($counts) after a clock step"
done
# The live trip in the recording's time: the input frames (not the gateway's 0x2xx-0x7xx, not the
# markers) before the first GW_ALARM at level 2, looked up in the recording.
n_in=$(awk '{ split($3, f, "#"); c = substr(f[1], 1, 1) }
  f[1] == "201" && substr(f[2], 2, 1) ~ /[26AE]/ { print n + 0; found = 1; exit }
  c == "1" { n++ } END { if (!found) print "none" }' "$WORK_DIR/clock_bus.log")
[ "$n_in" != none ] || fail "no trip on the bus (offline: at $trip_off s)"
trip_live=$(awk -v n="$n_in" -v t0="$t0" 'NR == n { printf "%.1f", substr($1, 2, length($1) - 2) - t0; exit }' \
  "$WORK_DIR/clock_whole.log")
echo "daemon_heartbeat: clock steps: trip latched live at $trip_live s of the recording ($n_in input frames before it), offline at $trip_off s"
awk -v a="$trip_live" -v b="$trip_off" 'BEGIN { d = a - b; if (d < 0) d = -d; exit !(d <= 2.0) }' ||
  fail "the live trip ($trip_live s) is more than 2 s from the offline one ($trip_off s)"
last=$(grep " 201#" "$WORK_DIR/clock_bus.log" | tail -n 1 | sed 's/.*#//')
case $(echo "$last" | cut -c2) in 2 | 6 | A | E) ;; *) fail "the last GW_ALARM ($last) is not at trip level: not latched" ;; esac
echo "daemon_heartbeat: PASS (heartbeat; clock steps: frames in every phase, trip live $trip_live s / offline $trip_off s, latched)"
