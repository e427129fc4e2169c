#!/bin/sh
# pumptherm telemetry, and identify/estimate --log: one pump's dq telemetry straight from a
# candump recording of the plant simulator. Checks: a row per paired current/voltage frame at
# the drive's 100 Hz; identify --log gives exactly what identify -i gives on telemetry's CSV; the
# frame temperature agrees with the simulator's measured CSV; a bad line and a line without a
# timestamp are skipped with file:line and counted; the screen format and relative stamps (-t z,
# -t d) give the same rows; a directory or a node ID without frames is exit 2 naming it.
#   telemetry_cli_test.sh PUMPTHERM
set -u
exe=$1
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*"; exit 1; }

"$exe" plant demo --duration-s 60 --quiet --out "$tmp/d" || fail "plant demo"
sed -e '100a this is not a candump line' -e '101a \  can0  103   [8]  FC FF 58 02 00 00 00 00' \
  "$tmp/d/demo.log" > "$tmp/bad.log"
"$exe" telemetry --log "$tmp/bad.log" --node-id 3 -o "$tmp/p3.csv" 2> "$tmp/err.txt" || { cat "$tmp/err.txt"; fail "telemetry"; }
cat "$tmp/err.txt"
grep -q "bad.log:101:1: skipped" "$tmp/err.txt" || fail "the bad line is not named with file:line"
grep -q "1 bad" "$tmp/err.txt" || fail "the bad line is not counted"
grep -q "bad.log:103: skipped: no timestamp" "$tmp/err.txt" || fail "the line without a timestamp is not named"
grep -q "1 without a timestamp" "$tmp/err.txt" || fail "the line without a timestamp is not counted"
# The same recording in candump's screen format with -t a (-x's RX/TX on every other line): the
# same rows.
awk '{ split($3, f, "#"); n = length(f[2]) / 2; s = ""
       for (i = 0; i < n; i++) s = s " " substr(f[2], 2 * i + 1, 2)
       printf " %s  %s%s  %s   [%d] %s\n", $1, $2, (NR % 2 ? "  RX - -" : ""), f[1], n, s }' \
  "$tmp/d/demo.log" > "$tmp/screen.log"
"$exe" telemetry --log "$tmp/d/demo.log" --node-id 3 -o "$tmp/p3log.csv" 2>/dev/null || fail "telemetry on the log"
"$exe" telemetry --log "$tmp/screen.log" --node-id 3 -o "$tmp/p3screen.csv" 2>/dev/null || fail "telemetry on the screen format"
cmp -s "$tmp/p3log.csv" "$tmp/p3screen.csv" || fail "the screen format gives other rows than the log format"
rows=$(($(wc -l < "$tmp/p3.csv") - 1))
[ "$rows" -ge 5900 ] && [ "$rows" -le 6000 ] || fail "$rows rows for 60 s at 100 Hz"
head -n 1 "$tmp/p3.csv" | grep -qx "time_s,id_A,iq_A,ud_V,uq_V,speed_rpm,frame_degC,ambient_degC" || fail "header: $(head -n 1 "$tmp/p3.csv")"
# The last frame temperature against the simulator's measured sensor (both 0.1 K steps).
python3 - "$tmp/p3.csv" "$tmp/d/pump3.measured.csv" <<'PY' || fail "frame temperature"
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1])))
meas = list(csv.DictReader(open(sys.argv[2])))
last, truth = float(rows[-1]["frame_degC"]), float(meas[-1]["frame_degC"])
assert abs(last - truth) <= 0.3, (last, truth)
assert all(len(r["iq_A"]) < 14 for r in rows), "numbers carry binary noise"
print(f"frame_degC at the end: {last} (simulator's sensor {truth}); {len(rows)} rows")
PY
# The same recording with candump -t z stamps (since the first frame) and -t d stamps (since the
# previous frame): both read as seconds since the start, the same rows as Unix time's.
python3 - "$tmp/d/demo.log" "$tmp/z.log" "$tmp/dd.log" <<'PY' || fail "relative stamps"
import sys
lines = open(sys.argv[1]).read().splitlines()
us = [int(l[1:l.index(")")].replace(".", "")) for l in lines]
rest = [l[l.index(")"):] for l in lines]
fmt = lambda t: f"({t // 1000000}.{t % 1000000:06d}"
open(sys.argv[2], "w").write("".join(fmt(t - us[0]) + r + "\n" for t, r in zip(us, rest)))
prev = [us[0]] + us[:-1]
open(sys.argv[3], "w").write("".join(fmt(t - p) + r + "\n" for t, p, r in zip(us, prev, rest)))
PY
"$exe" telemetry --log "$tmp/z.log" --node-id 3 -o "$tmp/p3z.csv" 2> "$tmp/z.txt" || fail "telemetry on -t z"
"$exe" telemetry --log "$tmp/dd.log" --node-id 3 -o "$tmp/p3d.csv" 2> "$tmp/d.txt" || fail "telemetry on -t d"
grep -q "since the first frame" "$tmp/z.txt" || { cat "$tmp/z.txt"; fail "-t z stamps not named"; }
grep -q "since the previous frame" "$tmp/d.txt" || { cat "$tmp/d.txt"; fail "-t d stamps not named"; }
cmp -s "$tmp/p3z.csv" "$tmp/p3d.csv" || fail "-t d stamps give other rows than -t z"
cut -d, -f2- "$tmp/p3log.csv" > "$tmp/abs.cols"
cut -d, -f2- "$tmp/p3z.csv" > "$tmp/z.cols"
cmp -s "$tmp/abs.cols" "$tmp/z.cols" || fail "relative stamps give other values than Unix time"
"$exe" telemetry --log "$tmp/d" --node-id 3 > /dev/null 2> "$tmp/dir.txt"
[ $? -eq 2 ] || fail "a directory as --log: expected exit 2"
grep -q "is a directory" "$tmp/dir.txt" || { cat "$tmp/dir.txt"; fail "a directory as --log: message"; }
"$exe" identify -i "$tmp/p3.csv" -o "$tmp/a.csv" 2>/dev/null || fail "identify -i"
"$exe" identify --log "$tmp/d/demo.log" --node-id 3 -o "$tmp/b.csv" 2>/dev/null || fail "identify --log"
cmp -s "$tmp/a.csv" "$tmp/b.csv" || fail "identify --log differs from identify -i on telemetry's CSV"
"$exe" estimate --model tmp-generic --log "$tmp/d/demo.log" --node-id 3 -o "$tmp/e.csv" 2>/dev/null || fail "estimate --log"
# The daemon's CSV: a row per thermal step (1 s) of the recording (100 telemetry rows a second).
steps=$(($(wc -l < "$tmp/e.csv") - 1))
[ "$steps" -ge $((rows / 100 - 2)) ] && [ "$steps" -le $((rows / 100 + 1)) ] ||
  fail "estimate --log: $steps rows for $rows telemetry rows, not one per second"
"$exe" telemetry --log "$tmp/d/demo.log" --node-id 9 > /dev/null 2> "$tmp/e9.txt"
[ $? -eq 2 ] || fail "node ID 9 (no frames): expected exit 2"
grep -q "no paired current and voltage frames of node ID 9" "$tmp/e9.txt" || { cat "$tmp/e9.txt"; fail "node ID 9 message"; }
echo "PASS"
