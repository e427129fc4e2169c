#!/usr/bin/env bash
# `pumptherm estimate` on a CSV is the daemon's pump estimator: the daemon's CSV with the
# mismatch test's verdict (mismatch_state, mismatch_effect, mismatch_value) and, by default on
# tmp-generic, the disturbance-state filter (--filter standard: the standard one). Truth from
# `pumptherm simulate` on tmp-generic, the frame as the measurement: on the nominal model the
# verdict ends consistent; with the frame-to-ambient resistance x4 (cooling lost) it ends a plant
# change, and the default filter keeps the rotor within its +-2 sd where the standard filter does
# not; a reading that steps +3 K goes into its sensor offset (frame_sensor_offset_K).
set -euo pipefail
exe=$1
models=$2  # estimators/models of the source tree
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*"; exit 1; }
{
  echo "time_s,speed_rpm,id_A,iq_A,ambient_C"
  for t in $(seq 0 5 3600); do echo "$t,21000,0,3,22"; done
} > "$tmp/in.csv"
sed 's/resistance_K_per_W = 0.6 /resistance_K_per_W = 2.4 /' "$models/tmp-generic.toml" > "$tmp/cooling-lost.toml"
cmp -s "$models/tmp-generic.toml" "$tmp/cooling-lost.toml" && fail "the frame-to-ambient edge was not edited"
# measured FILE MODEL: the inputs with the simulated frame as frame_degC, the truth kept in truth_MODEL.
measured() {
  "$exe" simulate --model "$2" --input "$tmp/in.csv" --initial-C 22 --output "$tmp/truth_$1.csv"
  paste -d, "$tmp/in.csv" <(awk -F, 'NR == 1 { for (i = 1; i <= NF; i++) if ($i == "frame_degC") c = i; print "frame_degC"; next } { print $c }' "$tmp/truth_$1.csv") > "$tmp/meas_$1.csv"
}
measured healthy "$models/tmp-generic.toml"
measured lost "$tmp/cooling-lost.toml"
est() { "$exe" estimate --model tmp-generic --input "$tmp/meas_$1.csv" --output "$tmp/est_$1_$2.csv" "${@:3}"; }
est healthy std --filter standard
est lost std --filter standard
est lost dist
# col FILE NAME: the last row's value of column NAME.
col() { awk -F, -v n="$2" 'NR == 1 { for (i = 1; i <= NF; i++) if ($i == n) c = i; next } { v = $c } END { print v }' "$1"; }
for c in mismatch_state mismatch_effect mismatch_value; do
  head -n 1 "$tmp/est_lost_std.csv" | tr ',' '\n' | grep -qx "$c" || fail "no $c column"
done
h=$(col "$tmp/est_healthy_std.csv" mismatch_state)
s=$(col "$tmp/est_lost_std.csv" mismatch_state)
e=$(col "$tmp/est_lost_std.csv" mismatch_effect)
v=$(col "$tmp/est_lost_std.csv" mismatch_value)
echo "verdict at 3600 s: nominal $h; cooling lost $s, $e $v"
[[ $h == consistent ]] || fail "nominal data: verdict $h, not consistent"
[[ $s == plant_change ]] || fail "cooling lost: verdict $s, not plant_change"
truth=$(col "$tmp/truth_lost.csv" rotor_degC)
r_std=$(col "$tmp/est_lost_std.csv" rotor_degC); sd_std=$(col "$tmp/est_lost_std.csv" rotor_sd_K)
r_dist=$(col "$tmp/est_lost_dist.csv" rotor_degC); sd_dist=$(col "$tmp/est_lost_dist.csv" rotor_sd_K)
echo "rotor at 3600 s: truth $truth; standard $r_std +- $sd_std; disturbance states $r_dist +- $sd_dist"
awk -v t="$truth" -v a="$r_std" -v sa="$sd_std" -v b="$r_dist" -v sb="$sd_dist" 'function abs(x) { return x < 0 ? -x : x }
  BEGIN { exit !(abs(b - t) <= 2 * sb && abs(a - t) > 2 * sa && abs(b - t) < abs(a - t)) }' ||
  fail "the disturbance-state filter does not cover the rotor where the standard filter fails"
# A frame reading that steps +3 K at 1800 s: the disturbance filter takes it as the sensor's offset
# (frame_sensor_offset_K, as the daemon's CSV) and its frame stays on the truth.
awk -F, 'BEGIN { OFS = "," } NR > 1 && $1 >= 1800 { $NF = $NF + 3 } { print }' "$tmp/meas_healthy.csv" > "$tmp/meas_offset.csv"
est offset dist
o=$(col "$tmp/est_offset_dist.csv" frame_sensor_offset_K)
f=$(col "$tmp/est_offset_dist.csv" frame_degC); ft=$(col "$tmp/truth_healthy.csv" frame_degC)
echo "reading +3 K from 1800 s: offset $o K at 3600 s; frame $f against $ft true"
awk -v o="$o" -v f="$f" -v t="$ft" 'function abs(x) { return x < 0 ? -x : x }
  BEGIN { exit !(abs(o - 3) <= 0.5 && abs(f - t) <= 1) }' ||
  fail "the stepped reading was not taken as the sensor's offset"
# The same with the 5 s rows split into 1 s steps (--max-step-s): the readings are 5 steps apart.
"$exe" estimate --model tmp-generic --input "$tmp/meas_offset.csv" \
  --output "$tmp/est_offset_split.csv" --max-step-s 1
o=$(col "$tmp/est_offset_split.csv" frame_sensor_offset_K)
f=$(col "$tmp/est_offset_split.csv" frame_degC)
echo "the same in 1 s steps: offset $o K; frame $f against $ft true"
awk -v o="$o" -v f="$f" -v t="$ft" 'function abs(x) { return x < 0 ? -x : x }
  BEGIN { exit !(abs(o - 3) <= 0.5 && abs(f - t) <= 1) }' ||
  fail "in 1 s steps the stepped reading was not taken as the sensor's offset"
set +e
"$exe" estimate --model tmp-generic --input "$tmp/meas_lost.csv" --measure frame,rotor \
  --output "$tmp/bad.csv" 2> "$tmp/err.txt"
rc=$?
set -e
[[ $rc == 2 ]] || fail "the pump estimator with two measured nodes exited $rc, not 2"
echo PASS
