#!/usr/bin/env bash
# The main job on the bundled default: the demo of three turbo pumps, end to end, with no
# kernel CAN needed.
#   1. `pumptherm plant demo` simulates 20 minutes of three pumps (drive electrics, thermal
#      truth, sensors) and writes their CAN traffic as a candump log; pump 3's cooling fails.
#   2. `pumpthermd -r` runs the gateway offline on that recording, showing a live-style table
#      (20 minutes in about 20 seconds), and writes its estimates, output frames and LCM log.
#   3. `pumptherm plot` draws per pump every estimated node against the truth and the
#      estimate's error (estimate minus truth, with its +-2 sd band), the cooling failure, the
#      daemon's diagnosis and the alarms; the winding from resistance and the magnet from flux
#      where the daemon has them.
# Options: --fast (no pacing), --live (the same on vcan0 with canplayer; needs kernel vcan;
#          builds the LCM viewer's jars, so that $build/tools/pumptherm-spy runs).
set -euo pipefail
cd "$(dirname "$0")/.."
pace=60
live=0
for arg in "$@"; do
  case "$arg" in
    --fast) pace=0 ;;
    --live) live=1 ;;
    -h|--help) sed -n '2,14p' "$0"; exit 0 ;;
    *) echo "demo.sh: unknown option '$arg' (see --help)" >&2; exit 2 ;;
  esac
done
out=${PUMPTHERM_DEMO_DIR:-demo-out}
build=${PUMPTHERM_BUILD_DIR:-build}
cmake -S . -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo >/dev/null
targets=(pumpthermd pumptherm)
# Live, the README sends the user to the LCM viewer: build what it needs too.
[[ $live == 1 ]] && targets+=(pumptherm_lcm_types_jar pumptherm_spy_plugin_jar)
cmake --build "$build" -j "${PUMPTHERM_JOBS:-$(nproc)}" --target "${targets[@]}"
mkdir -p "$out/estimates"

echo "== 1/3 simulating the plant: pumptherm plant demo --out $out"
"$build"/tools/pumptherm plant demo --out "$out"

if [[ $live == 1 ]]; then
  exec tools/demo-live.sh "$out"
fi

echo "== 2/3 the gateway on the recording: pumpthermd -r $out/demo.log (pace x$pace)"
"$build"/daemon/pumpthermd --config tools/demo/pumpthermd-demo.toml -r "$out/demo.log" \
  --table --table-period 60 --pace "$pace" --csv-dir "$out/estimates" \
  --output-log "$out/gateway.log" --lcm-log "$out/gateway.lcm" 2>&1 >"$out/pumpthermd.txt" |
  tee "$out/pumpthermd.err"
echo
tail -n 5 "$out/pumpthermd.txt"

echo "== 3/3 plotting: $out/demo.png"
"$build"/tools/pumptherm plot \
  --truth "$out/pump1.truth.csv" --estimate "$out/estimates/pump1.csv" --label "pump1" \
  --truth "$out/pump2.truth.csv" --estimate "$out/estimates/pump2.csv" --label "pump2" \
  --truth "$out/pump3.truth.csv" --estimate "$out/estimates/pump3.csv" --label "pump3 (cooling fails)" \
  --nodes winding,rotor,stator,frame --extra winding_resistance_degC=winding,magnet_flux_degC=rotor \
  --warning-C 100 --trip-C 120 --row-height 300 \
  --title "pumptherm demo: the gateway's estimates against the plant's truth, and their error" \
  --out "$out/demo.png"
echo
echo "Done. The plot is $out/demo.png; estimates per pump in $out/estimates/, the gateway's"
echo "CAN output in $out/gateway.log (candump format), its LCM messages in $out/gateway.lcm."
