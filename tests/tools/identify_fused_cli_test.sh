#!/bin/sh
# pumptherm identify --model / --config: the daemon's fused estimator over a recording, one pump,
# through the same Gateway path as `pumptherm estimate --log`. Checks, on a 3-minute demo
# recording (pumps 2 and 1: their winding from resistance is published from about 2 minutes
# on): every column identify writes (the winding from resistance among them) equals the daemon's
# CSV from `estimate --log` row for row, with --model and with the demo's configuration; the
# winding from resistance is published in some rows (so the comparison is not of empty columns);
# the summary is on stderr; --model with --input, --config without --pump and --block with
# --model are usage errors (exit 2) that say why; without --model identify --log still writes
# the DFRLS columns.
#   identify_fused_cli_test.sh PUMPTHERM SOURCE_DIR
set -u
exe=$1
src=$2
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*"; exit 1; }

"$exe" plant demo --duration-s 180 --quiet --out "$tmp/d" || fail "plant demo"
log="$tmp/d/demo.log"
conf="$src/tools/demo/pumpthermd-demo.toml"

"$exe" identify --model tmp-generic --log "$log" --node-id 2 -o "$tmp/i.csv" 2> "$tmp/i.txt" ||
  { cat "$tmp/i.txt"; fail "identify --model"; }
"$exe" estimate --model tmp-generic --log "$log" --node-id 2 -o "$tmp/e.csv" 2>/dev/null ||
  fail "estimate --log"
"$exe" identify --config "$conf" --pump pump1 --log "$log" -o "$tmp/ic.csv" 2> "$tmp/ic.txt" ||
  { cat "$tmp/ic.txt"; fail "identify --config"; }
"$exe" estimate --config "$conf" --pump pump1 --log "$log" -o "$tmp/ec.csv" 2>/dev/null ||
  fail "estimate --config"
cat "$tmp/ic.txt"
grep -q "winding from resistance published" "$tmp/i.txt" || fail "no summary on stderr"
grep -q "R0 .* ohm .*nameplate" "$tmp/ic.txt" || fail "no R0 against the nameplate in the summary"
head -n 1 "$tmp/i.csv" | grep -qx "time_s,winding_resistance_degC,winding_resistance_sd_K,magnet_flux_degC,magnet_flux_sd_K,voltage_reading,ident_status,r0_error,psi0_error,voltage_offset_V,identifier_winding_degC,identifier_status" ||
  fail "header: $(head -n 1 "$tmp/i.csv")"
python3 - "$tmp/i.csv" "$tmp/e.csv" "$tmp/ic.csv" "$tmp/ec.csv" <<'PY' || fail "identify --model against estimate --log"
import csv, math, sys
def rows(p): return list(csv.DictReader(open(p)))
for ident, est in ((sys.argv[1], sys.argv[2]), (sys.argv[3], sys.argv[4])):
    a, b = rows(ident), rows(est)
    assert len(a) == len(b) and len(a) >= 170, (ident, len(a), len(b))
    for k, (x, y) in enumerate(zip(a, b)):
        for c in x:
            assert x[c] == y[c], f"{ident}: row {k + 2} column {c}: {x[c]} != {y[c]}"
    published = sum(1 for r in a if not math.isnan(float(r["winding_resistance_degC"])))
    assert published >= 10, f"{ident}: winding from resistance published in {published} rows only"
    print(f"{ident}: {len(a)} rows equal to estimate's, winding from resistance in {published}")
PY

"$exe" identify --model tmp-generic --input "$tmp/i.csv" > /dev/null 2> "$tmp/u1.txt"
[ $? -eq 2 ] || fail "--model with --input: expected exit 2"
grep -q "give --log RECORDING" "$tmp/u1.txt" || { cat "$tmp/u1.txt"; fail "--model with --input: message"; }
"$exe" identify --config "$conf" --log "$log" > /dev/null 2> "$tmp/u2.txt"
[ $? -eq 2 ] || fail "--config without --pump: expected exit 2"
grep -q "go together" "$tmp/u2.txt" || { cat "$tmp/u2.txt"; fail "--config without --pump: message"; }
"$exe" identify --model tmp-generic --block 50 --log "$log" --node-id 1 > /dev/null 2> "$tmp/u3.txt"
[ $? -eq 2 ] || fail "--block with --model: expected exit 2"
grep -q "paper's DFRLS" "$tmp/u3.txt" || { cat "$tmp/u3.txt"; fail "--block with --model: message"; }
"$exe" identify --log "$log" --node-id 1 -o "$tmp/p.csv" 2>/dev/null || fail "identify --log (DFRLS)"
head -n 1 "$tmp/p.csv" | grep -qx "time_s,resistance_ohm,flux_Wb,winding_resistance_degC,status,winding_resistance_sd_K,flux_sd_Wb" ||
  fail "DFRLS header: $(head -n 1 "$tmp/p.csv")"
echo "PASS"
