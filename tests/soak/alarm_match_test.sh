#!/bin/sh
# The soak's alarm check (tests/soak/alarm_match.awk) can fail: on made-up truth and alarm changes
# for one pump (warning from 1000 s to 1600 s, trip never), it passes the matching answer and fails
# a false alarm, a missed warning, a late warning (60 s after the truth), a warning that does not
# clear and a trip nobody called for. Runs in well under a second.
#   alarm_match_test.sh   (from anywhere)
set -eu
here=$(cd "$(dirname "$0")" && pwd)
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
cat >"$tmp/summary.json" <<'JSON'
{
  "pumps": [
    {"name": "p", "interface": "can0", "node_id": 3, "max_C": 104.000, "trip_crossed_s": null, "above_warning_s": [[1000.00, 1600.00]], "frames_written": 1},
    {"name": "q", "interface": "can0", "node_id": 4, "max_C": 60.000, "trip_crossed_s": null, "above_warning_s": [], "frames_written": 1}
  ]
}
JSON
# Truth a row a minute: 60 degC, rising to 104 around the interval, no cooling fault.
awk 'BEGIN { print "time_s,winding_C,cooling_model"
  for (t = 0; t <= 3600; t += 60) {
    w = 60; if (t >= 700 && t < 1000) w = 60 + 40 * (t - 700) / 300; if (t >= 1000 && t <= 1600) w = 104
    if (t > 1600 && t < 1900) w = 104 - 44 * (t - 1600) / 300
    printf "%d,%.1f,0\n", t, w } }' >"$tmp/p.truth.csv"
awk 'BEGIN { print "time_s,winding_C,cooling_model"; for (t = 0; t <= 3600; t += 60) printf "%d,60,0\n", t }' >"$tmp/q.truth.csv"
fail=0
check() {  # check NAME WANT(PASS|FAIL) CHANGES...
  name=$1 want=$2
  shift 2
  printf '%s\n' "$@" >"$tmp/changes"
  if awk -v duration=3600 -v truth_dir="$tmp" -f "$here/alarm_match.awk" "$tmp/summary.json" "$tmp/changes" >"$tmp/out" 2>&1; then
    got=PASS
  else
    got=FAIL
  fi
  if [ "$got" = "$want" ]; then
    echo "ok: $name: $got"
  else
    echo "WRONG: $name: alarm_match.awk says $got, expected $want:"
    sed 's/^/    /' "$tmp/out"
    fail=1
  fi
}
# "A <s> <iface> <id> <level> <reason>": level 3 = not available (counts as normal).
start='A 0.0 can0 203 3 0'
startq='A 0.0 can0 204 3 0'
check "matching answer" PASS "$start" "$startq" 'A 61.0 can0 203 0 0' 'A 61.0 can0 204 0 0' \
  'A 1010.0 can0 203 1 1' 'A 1640.0 can0 203 0 0'
check "false alarm on the quiet pump" FAIL "$start" "$startq" 'A 61.0 can0 203 0 0' 'A 61.0 can0 204 0 0' \
  'A 1010.0 can0 203 1 1' 'A 1640.0 can0 203 0 0' 'A 2000.0 can0 204 1 1' 'A 2010.0 can0 204 0 0'
check "missed warning" FAIL "$start" "$startq" 'A 61.0 can0 203 0 0' 'A 61.0 can0 204 0 0'
check "late warning (60 s)" FAIL "$start" "$startq" 'A 61.0 can0 203 0 0' 'A 61.0 can0 204 0 0' \
  'A 1060.0 can0 203 1 1' 'A 1640.0 can0 203 0 0'
check "warning that never clears" FAIL "$start" "$startq" 'A 61.0 can0 203 0 0' 'A 61.0 can0 204 0 0' \
  'A 1010.0 can0 203 1 1'
check "trip nobody called for" FAIL "$start" "$startq" 'A 61.0 can0 203 0 0' 'A 61.0 can0 204 0 0' \
  'A 1010.0 can0 203 1 1' 'A 1200.0 can0 203 2 1'
[ "$fail" -eq 0 ] && echo "alarm_match_test: PASS" || echo "alarm_match_test: FAIL"
exit "$fail"
