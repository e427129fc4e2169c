#!/bin/sh
# Benchmark (prints figures, never passes or fails on time): pumpthermd's
# offline pipeline (`pumpthermd -r`) over the plant simulator's `fleet32` recording (32 pumps on
# can0 and can1, 1 h, 100 Hz fast telemetry + 10 Hz status: 24.2 million frames, 1.1 GB),
# measured in the same run as can-utils' `log2asc` converting the same log (the cost of merely
# reading and formatting it). Prints, for both: wall s, CPU s (user + system), frames/s per
# wall second and per CPU second (on a shared machine the CPU figures are the ones to quote), CPU
# s per bus-hour (the log holds 2 buses x 1 h = 2 bus-hours), peak RSS; and
# the CPU ratio pumpthermd / log2asc (goal: at most 2) and pumpthermd's peak RSS (goal: at most
# 20 MB). Then one JSON line with the same figures.
#
# Usage: tests/bench/offline_throughput.sh BUILD_DIR [LOG]
#   LOG defaults to /tmp/pumptherm-fleet32/fleet32.log, generated first when missing with
#   `BUILD_DIR/tools/pumptherm plant fleet32` (about 3 minutes; not for CI).
# Needs: /usr/bin/time (package time), log2asc (can-utils).
set -eu
build=${1:?usage: $0 BUILD_DIR [LOG]}
log=${2:-/tmp/pumptherm-fleet32/fleet32.log}
daemon="$build/daemon/pumpthermd"
tool="$build/tools/pumptherm"
here=$(cd "$(dirname "$0")" && pwd)
[ -x "$daemon" ] || { echo "$0: $daemon is not built" >&2; exit 2; }
command -v log2asc >/dev/null || { echo "$0: log2asc (can-utils) is not installed" >&2; exit 2; }
[ -x /usr/bin/time ] || { echo "$0: /usr/bin/time (package time) is not installed" >&2; exit 2; }
if [ ! -s "$log" ]; then
  [ -x "$tool" ] || { echo "$0: $log is missing and $tool is not built to make it" >&2; exit 2; }
  echo "generating $log (pumptherm plant fleet32) ..." >&2
  "$tool" plant fleet32 --out "$(dirname "$log")" --quiet >&2
fi
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

# The daemon's configuration for the recording: a00..a15 on can0, b00..b15 on can1, node IDs
# 0..15, the models the plant used (tools/plant/scenarios/fleet32.toml), LCM off (the messages
# are still encoded and handed to the offline sink; no output files are written).
{
  printf '[gateway]\nname = "fleet32"\nheartbeat_period_s = 0\n\n[alarms.levels]\n'
  printf 'winding = { warning_degC = 100.0, trip_degC = 120.0 }\n\n'
  sh "$here/../data/fleet32_pumps.sh"
} >"$work/fleet32.toml"
"$daemon" --check-config "$work/fleet32.toml" >/dev/null

frames=$(wc -l <"$log")
bytes=$(wc -c <"$log")
# measure NAME COMMAND...: runs it under /usr/bin/time; leaves "wall user sys maxrss_kB".
measure() {
  name=$1; shift
  /usr/bin/time -f '%e %U %S %M' -o "$work/$name.time" "$@" >"$work/$name.out" 2>"$work/$name.err" ||
    { echo "$0: $name failed:" >&2; cat "$work/$name.err" >&2; exit 1; }
}
cat "$log" >/dev/null   # into the page cache, so that neither pays for the disk
measure log2asc log2asc -I "$log" -O /dev/null can0 can1
measure pumpthermd "$daemon" --config "$work/fleet32.toml" -r "$log"
grep -q "" "$work/pumpthermd.err" && tail -n 3 "$work/pumpthermd.err" | sed 's/^/  pumpthermd: /' >&2 || true
# The daemon's own count: every frame of the log went through the pipeline.
echo "pumpthermd says: $(head -n 1 "$work/pumpthermd.out")"

report() {
  read -r wall user sys rss <"$work/$1.time"
  awk -v n="$1" -v f="$frames" -v w="$wall" -v u="$user" -v s="$sys" -v r="$rss" 'BEGIN {
    cpu = u + s
    printf "%-11s wall %7.2f s  cpu %7.2f s (user %.2f, sys %.2f)  %9.0f frames/s wall  %9.0f frames/cpu-s  %6.2f cpu s/bus-hour  peak RSS %6.1f MB\n",
           n, w, cpu, u, s, (w > 0 ? f / w : 0), (cpu > 0 ? f / cpu : 0), cpu / 2.0, r / 1024.0 }'
}
echo "log: $log ($frames frames, $bytes bytes; 2 buses x 1 h); $(nproc) cores, load $(cut -d' ' -f1-3 /proc/loadavg)"
report log2asc
report pumpthermd
read -r w1 u1 s1 r1 <"$work/log2asc.time"
read -r w2 u2 s2 r2 <"$work/pumpthermd.time"
awk -v f="$frames" -v w1="$w1" -v c1="$(echo "$u1 $s1" | awk '{ print $1 + $2 }')" -v r1="$r1" \
    -v w2="$w2" -v c2="$(echo "$u2 $s2" | awk '{ print $1 + $2 }')" -v r2="$r2" 'BEGIN {
  ratio = c1 > 0 ? c2 / c1 : 0
  printf "ratio pumpthermd/log2asc (cpu): %.2f (goal <= 2)\n", ratio
  printf "pumpthermd peak RSS: %.1f MB (goal <= 20)\n", r2 / 1024.0
  printf "{\"frames\": %d, \"bus_hours\": 2, \"log2asc\": {\"wall_s\": %.2f, \"cpu_s\": %.2f, \"frames_per_s\": %.0f, \"cpu_s_per_bus_hour\": %.3f, \"peak_rss_kB\": %d}, \"pumpthermd\": {\"wall_s\": %.2f, \"cpu_s\": %.2f, \"frames_per_s\": %.0f, \"cpu_s_per_bus_hour\": %.3f, \"peak_rss_kB\": %d}, \"cpu_ratio\": %.3f}\n",
         f, w1, c1, f / w1, c1 / 2, r1, w2, c2, f / w2, c2 / 2, r2, ratio }'
