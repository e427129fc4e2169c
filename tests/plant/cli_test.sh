#!/bin/sh
# `pumptherm plant` and `pumptherm plot` through the real executable: exit codes, errors that name
# where, same seed => same bytes, a PNG and an SVG that gnuplot drew, a clear error without gnuplot.
# Usage: cli_test.sh <pumptherm> <source dir>
set -u
exe=$1
src=$2
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*"; exit 1; }

# Same seed, same bytes (the first 20 s of the demo), through the CLI; another seed differs.
"$exe" plant demo --duration-s 20 --out "$tmp/a" -q || fail "plant demo run a"
"$exe" plant demo --duration-s 20 --out "$tmp/b" -q || fail "plant demo run b"
"$exe" plant demo --duration-s 20 --seed 5 --out "$tmp/c" -q || fail "plant demo run c"
for f in demo.log pump1.truth.csv pump3.measured.csv summary.json; do
  [ "$(sha256sum < "$tmp/a/$f")" = "$(sha256sum < "$tmp/b/$f")" ] || fail "$f differs between two runs with one seed"
done
[ "$(sha256sum < "$tmp/a/demo.log")" != "$(sha256sum < "$tmp/c/demo.log")" ] || fail "another seed gave the same log"
[ "$(wc -l < "$tmp/a/demo.log")" -eq $((3 * 20 * 210)) ] || fail "frame count of 3 pumps x 20 s"

# Progress bar: on a terminal only (util-linux `script` gives the command a pseudo-terminal).
"$exe" plant demo --duration-s 3 --out "$tmp/d" > /dev/null 2> "$tmp/err.txt" || fail "plant demo run d"
[ ! -s "$tmp/err.txt" ] || { cat "$tmp/err.txt"; fail "stderr not empty without a terminal"; }
if command -v script > /dev/null 2>&1; then
  script -qec "$exe plant demo --duration-s 3 --out $tmp/e" /dev/null | tr '\r' '\n' > "$tmp/tty.txt"
  grep -a -q "demo \[#*\.*\] *100 %" "$tmp/tty.txt" || { cat "$tmp/tty.txt"; fail "no progress bar on a terminal"; }
else
  echo "note: util-linux script not found, progress bar on a terminal not checked"
fi

# Bad input: exit 2, the message names the file, the line and the key.
printf '[scenario]\nname = "x"\nduration_s = 10\n[[pump]]\nmodel = "tmp-generic"\nspeed = 3\n' > "$tmp/bad.toml"
"$exe" plant "$tmp/bad.toml" --out "$tmp/bad" > "$tmp/out.txt" 2>&1
rc=$?
[ $rc -eq 2 ] || fail "bad scenario: exit $rc, expected 2"
grep -q "bad.toml:6: pump\[0\].speed: unknown key" "$tmp/out.txt" || { cat "$tmp/out.txt"; fail "error does not name line and key"; }
"$exe" plant no-such-scenario > "$tmp/out.txt" 2>&1
[ $? -eq 2 ] || fail "unknown scenario name: expected exit 2"
grep -q "'no-such-scenario': no such scenarios file; looked for:" "$tmp/out.txt" || { cat "$tmp/out.txt"; fail "unknown scenario message"; }
"$exe" plant --list | grep -q "^demo " || fail "--list does not list demo"

# Plot: PNG and SVG with an alarm timeline from an events CSV.
printf 'time_s,alarm_level,alarm_reason\n0,0,0\n8,1,1\n15,2,1\n' > "$tmp/events.csv"
"$exe" plot --truth "$tmp/a/pump3.truth.csv" --estimate "$tmp/a/pump3.measured.csv" --estimate-name RTD \
  --nodes frame --events "$tmp/events.csv" --warning-C 100 --trip-C 120 --out "$tmp/p.png" > "$tmp/out.txt" 2>&1 \
  || { cat "$tmp/out.txt"; fail "plot png"; }
[ "$(head -c 4 "$tmp/p.png" | od -An -c | tr -d ' ')" = "211PNG" ] || fail "not a PNG"
grep -q "alarm warning     8 s  trip    15 s" "$tmp/out.txt" || { cat "$tmp/out.txt"; fail "alarm moments not reported"; }
# Codes written as words (docs/daemon.md, "Names") read as the numbers.
printf 'time_s,alarm_level\n0,normal\n8,warning\n15,trip\n' > "$tmp/word_events.csv"
"$exe" plot --truth "$tmp/a/pump3.truth.csv" --nodes frame --events "$tmp/word_events.csv" \
  --out "$tmp/w.png" > "$tmp/out.txt" 2>&1 || { cat "$tmp/out.txt"; fail "plot with word events"; }
grep -q "alarm warning     8 s  trip    15 s" "$tmp/out.txt" || { cat "$tmp/out.txt"; fail "word-coded alarm levels not read"; }
# An estimate with its sd and a diagnosis: an error panel, the diagnosis marked, one legend that
# names only what is drawn (magnet_flux_degC has no value: "not available", no legend entry).
awk -F, 'NR == 1 { for (i = 1; i <= NF; i++) if ($i == "frame_degC") c = i; print "time_s,frame_degC,frame_sd_K,magnet_flux_degC,mismatch_state,mismatch_effect,mismatch_value"; next }
         { s = NR > 5 ? "plant_change" : "consistent"; e = NR > 10 ? "frame_ambient_resistance" : "none"
           print $1 "," $c + 0.3 ",0.2,nan," s "," e ",3.0" }' "$tmp/a/pump3.truth.csv" > "$tmp/est3.csv"
"$exe" plot --truth "$tmp/a/pump3.truth.csv" --estimate "$tmp/est3.csv" --nodes frame \
  --extra magnet_flux_degC=frame --mark 5=test --keep-script --out "$tmp/e.png" > "$tmp/out.txt" 2>&1 ||
  { cat "$tmp/out.txt"; fail "plot with an error panel"; }
script=$(sed -n 's/^gnuplot script and data kept in //p' "$tmp/out.txt")/plot.gp
grep -q "estimate minus truth" "$script" || fail "no error panel"
grep -q "diagnosis: cooling lost (frame-to-ambient resistance x3)" "$script" || fail "diagnosis not marked"
grep -q "min test" "$script" || fail "--mark not listed"
grep -q "magnet from flux: not available" "$script" || fail "an absent extra not said"
grep -q "keyentry.*magnet from flux" "$script" && fail "a legend entry for a curve not drawn"
[ "$(grep -c "^set key center" "$script")" = 1 ] || fail "not exactly one legend"
rm -rf "$(dirname "$script")"
# Alarm events in Unix time (the daemon's CSV) against the plant's relative truth: put on the
# truth's axis by --time-origin (the plant's start_epoch_s), else by their own first second; the
# choice is said on stderr.
printf 'time_s,alarm_level\n1767225601.0,0\n1767225608.0,1\n1767225615.0,2\n' > "$tmp/unix_events.csv"
"$exe" plot --truth "$tmp/a/pump3.truth.csv" --nodes frame --events "$tmp/unix_events.csv" --time-origin 1767225600 \
  --out "$tmp/u.png" > "$tmp/out.txt" 2>&1 || { cat "$tmp/out.txt"; fail "plot with Unix-time events"; }
grep -q "alarm warning     8 s  trip    15 s" "$tmp/out.txt" || { cat "$tmp/out.txt"; fail "Unix-time events not aligned by --time-origin"; }
grep -q "unix_events.csv: time_s is Unix time, drawn as time since 1767225600.000 (--time-origin" "$tmp/out.txt" \
  || { cat "$tmp/out.txt"; fail "alignment not said"; }
grep -q "pump3.truth.csv: time_s is time since its run's start, drawn as written" "$tmp/out.txt" \
  || { cat "$tmp/out.txt"; fail "relative time not said"; }
"$exe" plot --truth "$tmp/a/pump3.truth.csv" --nodes frame --events "$tmp/unix_events.csv" --out "$tmp/u.png" \
  > "$tmp/out.txt" 2>&1 || { cat "$tmp/out.txt"; fail "plot with Unix-time events, no origin"; }
grep -q "alarm warning     7 s  trip    14 s" "$tmp/out.txt" || { cat "$tmp/out.txt"; fail "Unix-time events: own first second"; }
grep -q "drawn as time since 1767225601.000 (the earliest Unix-time file's first whole second" "$tmp/out.txt" \
  || { cat "$tmp/out.txt"; fail "default origin not said"; }
"$exe" plot --truth "$tmp/a/pump1.truth.csv" --nodes winding,frame --out "$tmp/p.svg" > /dev/null 2>&1 || fail "plot svg"
grep -q "<svg" "$tmp/p.svg" || fail "not an SVG"
# Missing column: exit 2 naming it; no gnuplot: exit 1 saying so.
"$exe" plot --truth "$tmp/a/pump1.truth.csv" --nodes housing --out "$tmp/x.png" > "$tmp/out.txt" 2>&1
[ $? -eq 2 ] || fail "missing column: expected exit 2"
grep -q "housing_degC" "$tmp/out.txt" || fail "missing column not named"
"$exe" plot --truth "$tmp/a/pump1.truth.csv" --nodes frame --gnuplot "$tmp/no-gnuplot" --out "$tmp/x.png" > "$tmp/out.txt" 2>&1
[ $? -eq 1 ] || fail "absent gnuplot: expected exit 1"
grep -q "not installed" "$tmp/out.txt" || { cat "$tmp/out.txt"; fail "absent gnuplot message"; }
echo "PASS"
