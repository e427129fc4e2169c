#!/usr/bin/env bash
# `pumptherm estimate --paper-filter --magnet-column`: a magnet reading of the rotor enters the
# paper's filter (the rotor moves towards it, more so with a smaller sd); a node the model lacks
# is a usage error (exit 2), and so is the column without --paper-filter (the pump estimator reads
# the flux from the identifier).
set -euo pipefail
exe=$1
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*"; exit 1; }
{
  echo "time_s,speed_rpm,id_A,iq_A,ambient_C,frame_C,magnet_C"
  for t in $(seq 0 10 600); do echo "$t,21000,0,2,22,22,50"; done
} > "$tmp/in.csv"
run() { "$exe" estimate --paper-filter --model tmp-generic --input "$tmp/in.csv" --output "$tmp/$1.csv" "${@:2}"; }
run none
run loose --magnet-column magnet_C --magnet-sd-K 10
run tight --magnet-column magnet_C --magnet-sd-K 1
# col FILE NAME: the last row's value of column NAME.
col() { awk -F, -v n="$2" 'NR == 1 { for (i = 1; i <= NF; i++) if ($i == n) c = i; next } { v = $c } END { print v }' "$1"; }
r0=$(col "$tmp/none.csv" rotor_degC); r1=$(col "$tmp/loose.csv" rotor_degC); r2=$(col "$tmp/tight.csv" rotor_degC)
echo "rotor at 600 s: no magnet $r0, sd 10 K $r1, sd 1 K $r2 (reading 50)"
awk -v a="$r0" -v b="$r1" -v c="$r2" 'BEGIN { exit !(a < b && b < c && c > 45 && c <= 50.5) }' ||
  fail "the rotor does not move towards the magnet reading in order of its sd"
set +e
run bad --magnet-column magnet_C --magnet-node shaft 2> "$tmp/err.txt"
rc=$?
set -e
[[ $rc == 2 ]] || fail "unknown --magnet-node exited $rc, not 2"
grep -q "magnet-node: 'shaft'" "$tmp/err.txt" || fail "the error does not name the node: $(cat "$tmp/err.txt")"
set +e
"$exe" estimate --model tmp-generic --input "$tmp/in.csv" --output "$tmp/x.csv" --magnet-column magnet_C 2> "$tmp/err.txt"
rc=$?
set -e
[[ $rc == 2 ]] || fail "--magnet-column without --paper-filter exited $rc, not 2"
echo PASS
