#!/usr/bin/env bash
# `pumpthermd --check-config FILE --against LOG`: a configuration checked against a recording of
# its bus. On the vcan pipeline's recording (the plant's demo, 100 s, pumps at node IDs 1-3 on
# can0): the demo configuration fits (exit 0); a wrong node_id, a stale_after_s below the status
# period, a sensor range the readings leave, another interface name, relative stamps and a clock
# set back are each found and said with what to change (without the lag fit, which runs the
# pipeline some 15 times). On 10 minutes of the demo (frame RTD lag
# 30 s), a configuration without frame_sensor_lag_s is told the lag, and the interval holds 30 s.
#   commission_test.sh PUMPTHERMD PUMPTHERM SRC_DIR RECORDING
set -u
bin=$1
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
cp "$demo" "$tmp/demo.toml"

expect 0 "OK: nothing to change" -- "$bin" --check-config "$tmp/demo.toml" --against "$recording" --no-lag-fit
# pump2 configured at node 5: never heard, node 2 heard without a pump.
sed '/^name = "pump2"/{n;s/node_id = 2/node_id = 5/}' "$demo" > "$tmp/node.toml"
expect 2 "change: pump2 \(node_id = 5 on can0, line 43\) is never heard: no input frame of node 5 in the recording; heard without a pump: node 2 on can0 \([0-9]+ frames\) \(a wrong node_id\?\)" -- "$bin" --check-config "$tmp/node.toml" --against "$recording" --no-lag-fit
# Telemetry stale between two status frames (10 Hz) with stale_after_s = 0.05.
sed 's/^stale_after_s = 2.0/stale_after_s = 0.05/' "$demo" > "$tmp/stale.toml"
expect 2 "change: pump1: PUMP_STATUS comes every 0.10 s, not more often than alarms.stale_after_s = 0.05 s" -- "$bin" --check-config "$tmp/stale.toml" --against "$recording" --no-lag-fit
# A sensor range the frame readings (about 22-24 degC) leave.
sed 's/^hold_s = 2.0/hold_s = 2.0\nsensor_max_degC = 23.0/' "$demo" > "$tmp/range.toml"
expect 2 "change: pump1: frame_sensor_degC outside its plausible range \[-40, 23\] \(alarms.sensor_min_degC..sensor_max_degC \(-40..23\)\) in [0-9]+ of [0-9]+ frames, first [0-9.]+ at line [0-9]+" -- "$bin" --check-config "$tmp/range.toml" --against "$recording" --no-lag-fit
# Recorded on vcan0, configured for can0: read as the same bus, said so.
sed 's/ can0 / vcan0 /' "$recording" > "$tmp/vcan.log"
expect 0 "note: the recording is of vcan0, the configuration listens on can0: read as the same bus" -- "$bin" --check-config "$tmp/demo.toml" --against "$tmp/vcan.log" --no-lag-fit
# candump -t d stamps (the time since the previous frame), the log format.
awk '{ t = substr($1, 2, length($1) - 2); d = NR == 1 ? 0 : t - p; p = t;
       printf "(%010.6f) %s %s\n", d, $2, $3 }' "$recording" > "$tmp/delta.log"
expect 0 "note: the stamps are the time since the previous frame \(candump -t d\): read as seconds since the recording's start" -- "$bin" --check-config "$tmp/demo.toml" --against "$tmp/delta.log" --no-lag-fit
# The recording host's clock set back 30 s halfway.
awk -v n="$(wc -l < "$recording")" 'NR > n / 2 { t = substr($1, 2, length($1) - 2) - 30; $1 = sprintf("(%.6f)", t) } 1' \
  "$recording" > "$tmp/back.log"
expect 0 "note: the recording's clock goes back 1 time" -- "$bin" --check-config "$tmp/demo.toml" --against "$tmp/back.log" --no-lag-fit
: > "$tmp/empty.log"
expect 1 "empty.log: empty: no frame to run on" -- "$bin" --check-config "$tmp/demo.toml" --against "$tmp/empty.log" --no-lag-fit

# The sensor's lag from 10 minutes of the demo (true lag 30 s), the configuration without it.
"$pumptherm" plant demo --duration-s 600 --out "$tmp/plant" --quiet || { echo "FAIL: plant"; exit 1; }
# Pumps 1 and 2 (pump 3 loses its cooling at 4 min: too little data before, the lag not told).
grep -v '^frame_sensor_lag_s' "$demo" | awk '/^\[\[pump\]\]/ { n++ } n < 3' > "$tmp/nolag.toml"
"$bin" --check-config "$tmp/nolag.toml" --against "$tmp/plant/demo.log" > "$tmp/lag.txt" 2>&1
code=$?
cat "$tmp/lag.txt" | sed -n '/frame sensor lag/,$p'
[[ $code == 2 ]] || { echo "FAIL: exit $code, want 2 (a lag to set)"; fail=1; }
for pump in pump1 pump2; do
  line=$(grep -E "^  $pump +[0-9.]+ s \(interval" "$tmp/lag.txt")
  read -r low high < <(sed -E 's/.*interval ([0-9.]+)-([0-9.]+) s.*/\1 \2/' <<<"$line")
  if [[ -n $low ]] && awk -v l="$low" -v h="$high" 'BEGIN { exit !(l <= 30 && h >= 30 && h - l <= 12) }'; then
    echo "ok: $pump's lag interval $low-$high s holds the true 30 s"
  else
    echo "FAIL: $pump's lag: '$line' (want an interval of at most 12 s holding 30 s)"; fail=1
  fi
  grep -q "change: $pump: set frame_sensor_lag_s = " "$tmp/lag.txt" || { echo "FAIL: no change for $pump's lag"; fail=1; }
done

# The heat balance: beside a pump that matches the model, one whose iron makes 1.8 times the
# model's losses (15 minutes at 21000 r/min, gas-load changes): its filter needs about 40 % of the
# model's losses on the frame path, and model_losses_sd_rel = 0.3 is proposed for it alone.
cat > "$tmp/losses.toml" <<'EOF'
[scenario]
name = "losses"
description = "a pump whose iron makes 1.8 times the model's losses beside one that matches it"
duration_s = 900
seed = 7

[defaults]
model = "tmp-generic"
motor = "han2019-tmp"
interface = "can0"
ambient_C = 22.0
frame_sensor = { node = "frame", lag_s = 30.0 }
drive = { magnet_node = "rotor" }

[profile.gas]
segments = [
  { duration_s = 120, speed_rpm = 21000, iq_A = 3.0, iq_end_A = 3.0 },
  { duration_s = 200, iq_A = 2.2, iq_end_A = 2.4 },
  { duration_s = 260, iq_A = 3.4, iq_end_A = 3.2 },
  { duration_s = 320, iq_A = 2.7, iq_end_A = 2.9 },
]

[[pump]]
name = "nominal"
node_id = 1
profile = "gas"

[[pump]]
name = "iron"
node_id = 2
profile = "gas"
effects = [ { name = "iron_loss_scale", values = [1.8] } ]
EOF
"$pumptherm" plant "$tmp/losses.toml" --out "$tmp/losses" --quiet || { echo "FAIL: plant losses"; exit 1; }
cat > "$tmp/losses_pumpthermd.toml" <<'EOF'
[[can]]
interface = "can0"

[[pump]]
name = "nominal"
node_id = 1
frame_sensor_lag_s = 30.0
magnet_node = "rotor"

[[pump]]
name = "iron"
node_id = 2
frame_sensor_lag_s = 30.0
magnet_node = "rotor"
EOF
check=("$bin" --check-config "$tmp/losses_pumpthermd.toml" --against "$tmp/losses/losses.log" --no-lag-fit)
expect 2 "change: iron: set model_losses_sd_rel = 0.3 \(in the \[\[pump\]\] of line 10\): the filter needed \+[3-5][0-9] % of the model's losses on the frame path" -- "${check[@]}"
expect 2 "^  nominal +[-+][0-9.]+ W, [-+][0-9] % of [0-9.]+ W" -- "${check[@]}"
"${check[@]}" > "$tmp/losses.txt" 2>&1
if grep -q "change: nominal" "$tmp/losses.txt"; then echo "FAIL: a change proposed for the nominal pump"; fail=1; fi
# Stated, it is not proposed again; the balance is still listed.
echo 'model_losses_sd_rel = 0.3' >> "$tmp/losses_pumpthermd.toml"
expect 0 "^  iron +\+[0-9.]+ W, \+[3-5][0-9] % of [0-9.]+ W" -- "${check[@]}"
exit $fail
