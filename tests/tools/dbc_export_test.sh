#!/usr/bin/env bash
# `pumptherm dbc export`: the site DBC of the demo configuration (a pump renamed "pump-3.b" so
# that its messages need long names) decodes the gateway's CAN output of the vcan pipeline's
# recording in Debian's python3-canmatrix (site_dbc_check.py) and in `pumptherm dbc decode`
# without --node-id-limit, every frame known, nodes by name. Skips (77) without canmatrix unless
# CI=true.
#   dbc_export_test.sh PUMPTHERMD PUMPTHERM SRC_DIR RECORDING
set -u
pumpthermd=$1
pumptherm=$2
src=$3
recording=$4
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*"; exit 1; }
if ! /usr/bin/python3 -c 'import canmatrix.formats' 2>/dev/null; then
  [[ ${CI:-} == true ]] && fail "CI=true and python3-canmatrix is missing"
  echo "SKIP: python3-canmatrix is not installed (tools/setup.sh installs it)"; exit 77
fi
[[ -s $recording ]] || fail "$recording missing (built by vcan_pipeline_recording)"
# The demo's pumps, the third renamed, the winding's warning low enough to be raised in 100 s.
sed -e 's/^name = "pump3"/name = "pump-3.b"/' \
    -e 's/^winding = .*/winding = { warning_degC = 27.0, trip_degC = 120.0 }/' \
    "$src/tools/demo/pumpthermd-demo.toml" > "$tmp/site.toml"
"$pumpthermd" --config "$tmp/site.toml" -r "$recording" --output-log "$tmp/gw.log" > "$tmp/run.txt" 2>&1 ||
  { cat "$tmp/run.txt"; fail "pumpthermd -r"; }
"$pumptherm" dbc export --config "$tmp/site.toml" -o "$tmp/site.dbc" || fail "dbc export"
"$pumptherm" dbc export --config "$tmp/site.toml" --node-signals -o "$tmp/named.dbc" || fail "dbc export --node-signals"
grep -q 'BO_ 1155 GW_NODE_TEMP_pump_3_b_[0-9]*: 8 demo' "$tmp/site.dbc" ||
  fail "pump-3.b's GW_NODE_TEMP is not written with a short name"
grep -q 'BA_ "SystemMessageLongSymbol" BO_ 1155 "GW_NODE_TEMP_pump-3.b";' "$tmp/site.dbc" ||
  fail "pump-3.b's GW_NODE_TEMP has no long name"
/usr/bin/python3 "$src/tests/tools/site_dbc_check.py" "$tmp/site.dbc" "$tmp/named.dbc" "$tmp/gw.log" \
  pump1 pump2 pump-3.b || fail "canmatrix"
# Our decoder: every frame known without the node ID rule, the node named.
"$pumptherm" dbc decode --dbc "$tmp/site.dbc" "$tmp/gw.log" > "$tmp/decoded.json" 2> "$tmp/decode.err" ||
  fail "dbc decode"
grep -q ' frames decoded, 0 with IDs not in ' "$tmp/decode.err" || { cat "$tmp/decode.err"; fail "unknown frames"; }
"$pumptherm" dbc decode --dbc "$tmp/site.dbc" --format annotate -s "$tmp/gw.log" |
  grep -q 'GW_NODE_TEMP_pump-3.b(NodeIndex: winding' || fail "annotate does not name pump-3.b's winding"
echo "ok: the site DBC decodes the gateway's output by name ($(grep -c . "$tmp/gw.log") frames)"
