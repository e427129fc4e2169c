#!/bin/sh
# Soak of the offline pipeline: the plant's `fleet32-week` scenario (32 pumps on can0
# and can1, 7 days, five pumps with cooling trouble at known times) streamed through
# `pumpthermd -r`, nothing stored but the truth: plant -> FIFO -> daemon -> FIFO -> awk. Checks
# and prints, then says PASS or FAIL (exit 0 or 1; 2 for a usage or setup error):
#   1. every frame the plant wrote went through the gateway (its count), no malformed line;
#   2. alarms exactly those the truth calls for (tests/soak/alarm_match.awk, which states the
#      windows): each truth warning and trip answered by the gateway's GW_ALARM level within the
#      stated delays, warnings clearing after the truth falls back, nothing on any other pump;
#   3. resident memory flat: the daemon's VmRSS sampled every 10 min of log time; its highest
#      value in the last day (the last seventh of a shorter run, at least an hour) exceeds the
#      highest of the first day by at most 512 KB;
#   4. no drift in timing: every periodic output (GW_TEMPS_A/B, GW_HEALTH 1 s, GW_NODE_TEMP 1 s per
#      node, GW_IDENT 0.1 s,
#      GW_ALARM 0.1 s plus one frame per alarm change) has its period's count in every hour
#      (+-1; hours counted from the ID's first frame), its frames lag their schedule (first frame + k periods) by less than 1 ms on the
#      last day as on the first; each pump's thermal step count equals elapsed / period (+-1).
#
# Usage: tests/soak/offline_week.sh BUILD_DIR [HOURS] [SCENARIO]
#   HOURS: simulated hours (default 168, the week; the CTest short form `soak.offline_short`
#   uses 2). SCENARIO: a plant scenario with fleet32's pump names (default fleet32-week).
#   SOAK_WORK_DIR=DIR keeps the run's files there (default: a temporary directory, removed).
# Needs /usr/bin/time (package time) and awk. Plant and daemon run in parallel; what a simulated
# hour costs is in docs/robustness.md, "Soak".
set -eu
build=${1:?usage: $0 BUILD_DIR [HOURS] [SCENARIO]}
hours=${2:-168}
scenario=${3:-fleet32-week}
here=$(cd "$(dirname "$0")" && pwd)
daemon=$build/daemon/pumpthermd
tool=$build/tools/pumptherm
for x in "$daemon" "$tool"; do [ -x "$x" ] || { echo "$0: $x is not built" >&2; exit 2; }; done
[ -x /usr/bin/time ] || { echo "$0: /usr/bin/time (package time) is not installed" >&2; exit 2; }
case $hours in '' | *[!0-9]*) echo "$0: HOURS must be a whole number" >&2; exit 2 ;; esac
[ "$hours" -ge 1 ] || { echo "$0: HOURS must be at least 1" >&2; exit 2; }
if [ -n "${SOAK_WORK_DIR:-}" ]; then
  work=$SOAK_WORK_DIR
  mkdir -p "$work"
else
  work=$(mktemp -d)
  trap 'rm -rf "$work"' EXIT
fi
duration_s=$((hours * 3600))
# GW_NODE_TEMP (0x48x) carries each node of the model once a second, one frame per 1 s / nodes:
# tmp-generic (tests/data/fleet32_pumps.sh) has 4.
node_count=4

# The daemon's configuration: a00..a15 on can0, b00..b15 on can1 (node IDs 0..15), the plant's
# motor and model, levels and alarm timing as in the demo (tools/demo/pumpthermd-demo.toml), no
# heartbeat, LCM off (the messages are still encoded and handed to the offline sink).
cfg=$work/pumpthermd-soak.toml
{
  printf '[gateway]\nname = "soak"\nheartbeat_period_s = 0\nthermal_period_s = 1.0\n\n'
  printf '[alarms]\nhysteresis_K = 2.0\nhold_s = 2.0\nstale_after_s = 2.0\nforecast_horizon_s = 300.0\n'
  printf '[alarms.levels]\nwinding = { warning_degC = 100.0, trip_degC = 120.0 }\n\n'
  sh "$here/../data/fleet32_pumps.sh"
} >"$cfg"
"$daemon" --check-config "$cfg" >/dev/null

# The plant writes its log into a FIFO (fopen of a FIFO waits for the reader); the daemon writes
# its output frames into another, read by the awk that keeps the statistics.
plant_dir=$work/plant
mkdir -p "$plant_dir"
# The log is named after the scenario's own name ([scenario] name).
case $scenario in
  */* | *.toml) scenario_file=$scenario ;;
  *) scenario_file=$here/../../tools/plant/scenarios/$scenario.toml ;;
esac
[ -r "$scenario_file" ] || { echo "$0: cannot read the scenario $scenario_file" >&2; exit 2; }
name=$(sed -n 's/^name = "\(.*\)".*$/\1/p' "$scenario_file" | head -n 1)
rm -f "$plant_dir/$name.log" "$work/out.fifo"
mkfifo "$plant_dir/$name.log" "$work/out.fifo"

echo "soak: $scenario, $hours h simulated ($duration_s s); work directory $work; $(nproc) cores, load $(cut -d' ' -f1-3 /proc/loadavg)"
start_s=$(date +%s)
: >"$work/stats.txt"
: >"$work/rss.txt"
/usr/bin/time -f '%e %U %S %M' -o "$work/plant.time" \
  "$tool" plant "$scenario" --duration-s "$duration_s" --out "$plant_dir" --quiet \
  >"$work/plant.out" 2>"$work/plant.err" &
plant_pid=$!
/usr/bin/time -f '%e %U %S %M' -o "$work/daemon.time" \
  "$daemon" --config "$cfg" -r "$plant_dir/$name.log" --output-log "$work/out.fifo" \
  >"$work/daemon.out" 2>"$work/daemon.err" &
time_pid=$!
# The daemon is /usr/bin/time's child.
daemon_pid=""
for _ in 1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16 17 18 19 20; do
  daemon_pid=$(cat "/proc/$time_pid/task/$time_pid/children" 2>/dev/null | awk '{ print $1 }') || true
  [ -n "$daemon_pid" ] && break
  sleep 0.1
done
[ -n "$daemon_pid" ] || { echo "$0: cannot find the daemon's process" >&2; exit 2; }

# The statistics, and a memory sample each time the output's log time passes 10 more minutes.
/usr/bin/time -f '%e %U %S %M' -o "$work/awk.time" awk -v every=600 -v nodes="$node_count" -f "$here/output_stats.awk" "$work/out.fifo" |
  while read -r tag value rest; do
    if [ "$tag" = T ]; then
      rss=$(awk '$1 == "VmRSS:" { print $2 }' "/proc/$daemon_pid/status" 2>/dev/null) || rss=""
      [ -n "$rss" ] && echo "$value $rss" >>"$work/rss.txt"
      [ $((value % 43200)) -eq 0 ] &&
        echo "  log time $((value / 3600)) h: daemon VmRSS $rss kB ($(($(date +%s) - start_s)) s wall)"
    else
      echo "$tag $value $rest" >>"$work/stats.txt"
    fi
  done
rc=0
wait "$plant_pid" || { echo "soak: FAIL: the plant exited with an error:"; cat "$work/plant.err"; rc=1; }
wait "$time_pid" || { echo "soak: FAIL: the daemon exited with an error:"; tail -n 20 "$work/daemon.err"; rc=1; }
[ "$rc" -eq 0 ] || exit 1
wall_s=$(($(date +%s) - start_s))
touch "$work/rss.txt"

fail=0
bad() { echo "soak: FAIL: $*"; fail=1; }

# --- 1. every frame through the gateway ---
written=$(sed -n 's/^  "frames_written": \([0-9]*\),$/\1/p' "$plant_dir/summary.json")
read_line=$(head -n 1 "$work/daemon.out")
frames=$(echo "$read_line" | sed -n 's/^.*: \([0-9]*\) frames, .*$/\1/p')
malformed=$(echo "$read_line" | sed -n 's/^.*, \([0-9]*\) malformed lines skipped$/\1/p')
echo "frames: the plant wrote $written, the gateway read $frames ($malformed malformed lines)"
[ -n "$frames" ] && [ "$frames" = "$written" ] || bad "the gateway read $frames frames of $written"
[ "$malformed" = 0 ] || bad "$malformed malformed lines"

# --- 2. alarms against the truth ---
grep '^A ' "$work/stats.txt" >"$work/alarm_changes.txt" || true
awk -v duration="$duration_s" -v truth_dir="$plant_dir" -f "$here/alarm_match.awk" "$plant_dir/summary.json" "$work/alarm_changes.txt" \
  >"$work/alarms.txt" || true
cat "$work/alarms.txt"
grep -q '^alarms: PASS' "$work/alarms.txt" || bad "alarms do not match the truth (above)"

# --- 3. resident memory ---
window_s=$((duration_s / 7))
[ "$window_s" -ge 3600 ] || window_s=3600
awk -v w="$window_s" -v d="$duration_s" '
  { n++; if ($1 <= w && $2 > first) first = $2; if ($1 > d - w && $2 > last) last = $2
    if (min == "" || $2 < min) min = $2; if ($2 > max) max = $2 }
  END {
    printf "memory: %d VmRSS samples (every 600 s of log time); min %d kB, max %d kB; highest in the first %.1f h %d kB, in the last %.1f h %d kB: growth %d kB (limit 512)\n",
           n, min, max, w / 3600, first, w / 3600, last, last - first
    exit !(n >= 2 && first > 0 && last > 0 && last - first <= 512)
  }' "$work/rss.txt" || bad "resident memory is not flat (or too few samples)"

# --- 4. timing ---
expected_steps=$((duration_s - 1))
awk -v hours="$hours" -v nodes="$node_count" '
  $1 == "H" { key = $2 " " $3; id = $3; h = $4; n = $5
              if (h > hours - 2) next              # the last hour of each ID is partial
              if (substr(id, 1, 1) == "2") { alarm_n[key, h] = n; alarm_keys[key] = 1; next }
              exp_n = (substr(id, 1, 2) == "42") ? 36000 : (substr(id, 1, 2) == "48") ? 3600 * nodes : 3600
              checked++
              if (n < exp_n - 1 || n > exp_n + 1) { bad++; if (bad <= 5) printf "  %s hour %d: %d frames, expected %d\n", key, h, n, exp_n } }
  $1 == "A" { changes[$3 " " $4, int($2 / 3600)]++ }
  $1 == "L" { key = $2 " " $3; d = $4
              if (d == 0) { first_max = ($6 > first_max ? $6 : first_max) }
              if (d > last_day) { last_day = d; last_max = $6 } else if (d == last_day && $6 > last_max) last_max = $6
              if ($5 < -1 || $6 > 2000) { lag_bad++; if (lag_bad <= 5) printf "  %s day %d: lag %s..%s us\n", key, d, $5, $6 }
              if ($6 > worst) worst = $6 }
  END {
    for (key in alarm_keys) for (h = 0; h <= hours - 2; h++) {
      n = alarm_n[key, h] + 0; c = changes[key, h] + 0; checked++
      if (n < 36000 - 1 || n > 36000 + c + 1) { bad++; if (bad <= 5) printf "  %s hour %d: %d frames, expected 36000 + %d changes\n", key, h, n, c } }
    printf "timing: %d ID-hours checked, %d off their period count; schedule lag at most %.0f us on day 1, %.0f us on the last day, %.0f us in all (limit 2000)\n",
           checked, bad, first_max, last_max, worst
    exit !(bad == 0 && lag_bad == 0 && checked > 0)
  }' "$work/stats.txt" || bad "output timing drifted (above)"
awk -v want="$expected_steps" '
  started && NF == 9 && $8 ~ /^[0-9]+$/ && $2 > 0 {
    n++; if ($8 < lo || lo == "") lo = $8; if ($8 > hi) hi = $8
    if ($8 < want - 1 || $8 > want + 1) { bad++; printf "  %s: %d thermal steps, expected %d\n", $1, $8, want }
    if ($9 != 0) { bad++; printf "  %s: %d filter resets\n", $1, $9 } }
  $1 == "pump" && $9 == "resets" { started = 1 }
  END { printf "thermal steps: %d pumps, %d..%d steps each, expected %d (elapsed / 1 s); filter resets: see above if any\n", n, lo, hi, want
        exit !(n > 0 && bad == 0) }' "$work/daemon.out" || bad "thermal step counts are off"

# --- figures ---
echo "cost ($(nproc) cores; wall $wall_s s for $hours simulated hours):"
for p in plant daemon awk; do
  read -r w u s m <"$work/$p.time"
  awk -v p="$p" -v w="$w" -v u="$u" -v s="$s" -v m="$m" -v h="$hours" 'BEGIN {
    printf "  %-7s wall %8.1f s, cpu %8.1f s (%.2f s per simulated hour), peak RSS %.1f MB\n", p, w, u + s, (u + s) / h, m / 1024 }'
done
grep -c '^A ' "$work/stats.txt" | sed 's/^/alarm level changes on CAN (all pumps, including the start): /'
if [ "$fail" -eq 0 ]; then echo "soak: PASS"; else echo "soak: FAIL"; fi
exit "$fail"
