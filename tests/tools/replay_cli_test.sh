#!/usr/bin/env bash
# `pumptherm replay LOG --config FILE --levels ...`: the daemon's pipeline with what-if levels.
# On the vcan pipeline's recording (the plant's demo, 100 s), a winding warning level every
# pump reaches and a sensor trip level pump1 reaches: each pump's first warning and first trip are the moments `pumpthermd -r` with the same levels
# in its configuration raises them (its CSV's alarm_level), the least trip margin is negative
# exactly when a trip fired, and bad --levels are refused naming the argument.
#   replay_cli_test.sh PUMPTHERMD PUMPTHERM SRC_DIR RECORDING
set -u
pumpthermd=$1
pumptherm=$2
src=$3
recording=$4
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail=0
# shellcheck source=../common/expect.sh
source "$(dirname "${BASH_SOURCE[0]}")/../common/expect.sh"
[[ -s $recording ]] || { echo "FAIL: $recording missing (built by vcan_pipeline_recording)"; exit 1; }
demo=$src/tools/demo/pumpthermd-demo.toml

"$pumptherm" replay "$recording" --config "$demo" --levels winding=27/40 --levels pump1:sensor=/22.7 \
  > "$tmp/replay.txt" 2> "$tmp/replay.err" || { cat "$tmp/replay.err"; echo "FAIL: replay"; exit 1; }
sed 's/^/  | /' "$tmp/replay.txt"
# The same levels in the configuration, run by the daemon.
sed -e 's/^winding = .*/winding = { warning_degC = 27.0, trip_degC = 40.0 }/' \
    -e '/^name = "pump1"/a alarms.levels.sensor = { trip_degC = 22.7 }' "$demo" > "$tmp/levels.toml"
origin=$(head -n 1 "$recording" | sed 's/^(\([0-9.]*\)).*/\1/')
"$pumpthermd" --config "$tmp/levels.toml" -r "$recording" --csv-dir "$tmp/csv" --csv-time-origin "$origin" \
  > /dev/null 2>&1 || { echo "FAIL: pumpthermd -r"; exit 1; }
for pump in pump1 pump2 pump3; do
  # first_warning first_trip from the daemon's CSV (time_s since the first frame), "never" if none.
  read -r warn trip < <(awk -F, 'NR == 1 { for (i = 1; i <= NF; i++) c[$i] = i; next }
    { l = $c["alarm_level"]; t = $c["time_s"] }
    l != "normal" && l != "" && w == "" { w = sprintf("%.0f", t) } l == "trip" && p == "" { p = sprintf("%.0f", t) }
    END { print (w == "" ? "never" : w), (p == "" ? "never" : p) }' "$tmp/csv/$pump.csv")
  [[ $warn != never ]] && warn="$warn s"
  [[ $trip != never ]] && trip="$trip s"
  got=$(sed -n "/^$pump (/,/^$/p" "$tmp/replay.txt" | grep 'first warning')
  want="  first warning (or trip): $warn; first trip: $trip"
  if [[ $got == "$want" ]]; then
    echo "ok: $pump: $want (as pumpthermd -r)"
  else
    echo "FAIL: $pump: replay says '$got', pumpthermd -r '$want'"; fail=1
  fi
  # A negative least trip margin exactly when the pump tripped.
  margin=$(sed -n "/^$pump (/,/^$/p" "$tmp/replay.txt" | grep -m1 '    trip ' | sed -E 's/.*least margin ([-+][0-9.]+) K.*/\1/')
  if [[ ($trip == never && $margin == +*) || ($trip != never && $margin == -*) ]]; then
    echo "ok: $pump: least trip margin $margin K (first trip: $trip)"
  else
    echo "FAIL: $pump: least trip margin $margin K but first trip: $trip"; fail=1
  fi
done
expect 2 "--levels winding=9x/110: '9x' is not a temperature in degC" -- "$pumptherm" replay "$recording" --config "$demo" --levels winding=9x/110
expect 2 "levels for 'housing': pump 'pump1' \(model tmp-generic\) has no node 'housing' \(its nodes: frame, stator, winding, rotor" -- "$pumptherm" replay "$recording" --config "$demo" --levels housing=90/110
# --pace publishes on LCM: without a URL it says so (nothing is sent from this test).
grep -v '^url = ' "$demo" > "$tmp/nolcm.toml"
expect 2 "--pace publishes on LCM: give --lcm-url or set lcm.url" -- "$pumptherm" replay "$recording" --config "$tmp/nolcm.toml" --pace 10
# --pace: watch follows the replay over UDP multicast, inside a network namespace made here
# (multicast on its loopback only, ttl=0: nothing leaves it). Needs root and netns, else skipped.
ns="pumptherm-replay-$$"
if [[ $(id -u) -eq 0 ]] && ip netns add "$ns" 2>/dev/null; then
  trap 'ip netns del "$ns" 2>/dev/null || true; rm -rf "$tmp"' EXIT
  ip -n "$ns" link set lo up
  ip -n "$ns" link set lo multicast on
  ip -n "$ns" route add 224.0.0.0/4 dev lo
  url='udpm://239.255.76.67:7667?ttl=0'
  ip netns exec "$ns" "$pumptherm" replay "$recording" --config "$tmp/nolcm.toml" --pace 25 \
    --lcm-url "$url" > /dev/null 2>&1 &
  out=$(ip netns exec "$ns" "$pumptherm" watch --url "$url" --period-s 1 --count 2) || true
  wait
  if grep -q pump1 <<<"$out" && grep -q pump3 <<<"$out" && grep -q 'winding ' <<<"$out"; then
    echo "ok: pumptherm watch follows the paced replay (pump1..pump3, nodes by name)"
  else
    echo "FAIL: watch did not show the replay's pumps:"; echo "$out"; fail=1
  fi
else
  echo "skip: --pace with watch needs root and ip netns"
fi
exit $fail
