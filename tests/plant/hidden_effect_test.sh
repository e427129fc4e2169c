#!/bin/sh
# Hidden-effect data from `pumptherm plant`: the bundled scenario
# hidden-frame-mass hides 3 kJ/K on the frame of saheba2010-baseline; the discrepancy workflow,
# not told about it, must name frame_thermal_mass with an interval holding 3000 J/K and shrink the
# validation gap. The same for guide-pump3 (the operator's guide: a cooling path 1.8 times the
# model's, named frame_ambient_resistance). Bad `effects` entries: exit 2 naming line and key.
# Usage: hidden_effect_test.sh <pumptherm>
set -u
exe=$1
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*"; exit 1; }

"$exe" plant hidden-frame-mass --out "$tmp/d" -q || fail "plant hidden-frame-mass"
"$exe" discrepancy --model saheba2010-baseline --train "$tmp/d/train.measured.csv" \
  --validate "$tmp/d/validate.measured.csv" --out "$tmp/r" > "$tmp/out.txt" 2>&1 || { cat "$tmp/out.txt"; fail "discrepancy"; }
cat "$tmp/out.txt"
python3 - "$tmp/r/report.json" <<'PY' || fail "report does not name the hidden effect"
import json, sys
r = json.load(open(sys.argv[1]))
assert r["verdict"] == "named" and r["effect"] == "frame_thermal_mass", (r["verdict"], r["effect"])
p = r["effects"][0]["parameters"][0]
lo, hi = p["ci95"]
assert lo <= 3000.0 <= hi, f"3000 J/K outside the 95 % interval {lo}..{hi}"
g = r["gap"]["validate"]
before, after = g["before"]["overall"]["rmse_K"], g["after"]["overall"]["rmse_K"]
assert after < 0.5 * before, (before, after)
print(f"named frame_thermal_mass: {p['value']:.0f} J/K ({lo:.0f}..{hi:.0f}), validation RMSE {before:.2f} -> {after:.2f} K")
PY

# The operator's guide's scenario: tmp-generic whose cooling path is 1.8 times its model's.
"$exe" plant guide-pump3 --out "$tmp/g" -q || fail "plant guide-pump3"
"$exe" discrepancy --model tmp-generic --train "$tmp/g/train.measured.csv" \
  --validate "$tmp/g/validate.measured.csv" --out "$tmp/gr" > "$tmp/gout.txt" 2>&1 || { cat "$tmp/gout.txt"; fail "discrepancy (guide)"; }
cat "$tmp/gout.txt"
python3 - "$tmp/gr/report.json" <<'PY' || fail "the guide's report does not name the hidden cooling effect"
import json, sys
r = json.load(open(sys.argv[1]))
assert r["verdict"] == "named" and r["effect"] == "frame_ambient_resistance", (r["verdict"], r["effect"])
p = r["effects"][0]["parameters"][0]
assert abs(p["value"] - 1.8) < 0.1, p["value"]
g = r["gap"]["validate"]
before, after = g["before"]["overall"]["rmse_K"], g["after"]["overall"]["rmse_K"]
assert after < 0.2 * before, (before, after)
print(f"guide-pump3: named frame_ambient_resistance x{p['value']:.2f}, validation RMSE {before:.2f} -> {after:.2f} K")
PY

# Bad effects: unknown name, a sensor effect, a wrong number of values.
printf '[scenario]\nname = "x"\nduration_s = 10\ncan_log = false\n[[pump]]\nmodel = "tmp-generic"\nsegments = [{ duration_s = 10 }]\neffects = [{ name = "magic", values = [1.0] }]\n' > "$tmp/bad1.toml"
"$exe" plant "$tmp/bad1.toml" --out "$tmp/b1" > "$tmp/e1.txt" 2>&1
[ $? -eq 2 ] || fail "unknown effect: expected exit 2"
grep -q "bad1.toml:8: pump\[0\].effects\[0\].name: unknown effect 'magic'" "$tmp/e1.txt" || { cat "$tmp/e1.txt"; fail "unknown effect message"; }
sed 's/"magic", values = \[1.0\]/"sensor_lag", values = [30.0]/' "$tmp/bad1.toml" > "$tmp/bad2.toml"
"$exe" plant "$tmp/bad2.toml" --out "$tmp/b2" > "$tmp/e2.txt" 2>&1
[ $? -eq 2 ] || fail "sensor effect: expected exit 2"
grep -q "is a sensor effect: set frame_sensor.lag_s" "$tmp/e2.txt" || { cat "$tmp/e2.txt"; fail "sensor effect message"; }
sed 's/"magic", values = \[1.0\]/"rotor_loss", values = [1.0, 2.0]/' "$tmp/bad1.toml" > "$tmp/bad3.toml"
"$exe" plant "$tmp/bad3.toml" --out "$tmp/b3" > "$tmp/e3.txt" 2>&1
[ $? -eq 2 ] || fail "wrong value count: expected exit 2"
grep -q "effects\[0\].values: 'rotor_loss' takes 1 value(s)" "$tmp/e3.txt" || { cat "$tmp/e3.txt"; fail "value count message"; }
echo "PASS"
