#!/usr/bin/env bash
# The main job on the bundled default: the demo of three turbo pumps, end to end, with no
# kernel CAN needed.
#   1. `pumptherm plant demo` simulates 20 minutes of three pumps (drive electrics, thermal
#      truth, sensors) and writes their CAN traffic as a candump log; pump 3's cooling fails.
#   2. `pumpthermd -r` runs the gateway offline on that recording, showing a live-style table
#      (20 minutes in about 20 seconds), and writes its estimates, output frames and LCM log.
#   3. `pumptherm plot` draws every estimated node with its +-2 sd band against the truth, the
#      winding temperature from resistance and the magnet temperature from flux, and the alarms.
# Options: --fast (no pacing), --live (the same on vcan0 with canplayer; needs kernel vcan).
set -euo pipefail
cd "$(dirname "$0")/.."
pace=60
live=0
for arg in "$@"; do
  case "$arg" in
    --fast) pace=0 ;;
    --live) live=1 ;;
    -h|--help) sed -n '2,11p' "$0"; exit 0 ;;
    *) echo "demo.sh: unknown option '$arg' (see --help)" >&2; exit 2 ;;
  esac
done
out=${PUMPTHERM_DEMO_DIR:-demo-out}
build=${PUMPTHERM_BUILD_DIR:-build}
cmake -S . -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo >/dev/null
cmake --build "$build" -j "${PUMPTHERM_JOBS:-$(nproc)}" --target pumpthermd pumptherm
mkdir -p "$out/estimates"

echo "== 1/3 simulating the plant: pumptherm plant demo --out $out"
"$build"/tools/pumptherm plant demo --out "$out"
origin=$(head -n 1 "$out/demo.log" | sed 's/^(\([0-9]*\)\..*/\1/')

if [[ $live == 1 ]]; then
  exec tools/demo-live.sh "$out"
fi

echo "== 2/3 the gateway on the recording: pumpthermd -r $out/demo.log (pace x$pace)"
"$build"/daemon/pumpthermd --config tools/demo/pumpthermd-demo.toml -r "$out/demo.log" \
  --table --table-period 60 --pace "$pace" --csv-dir "$out/estimates" --csv-time-origin "$origin" \
  --output-log "$out/gateway.log" --lcm-log "$out/gateway.lcm" 2>&1 >"$out/pumpthermd.txt" |
  tee "$out/pumpthermd.err"
echo
tail -n 5 "$out/pumpthermd.txt"

echo "== 3/3 plotting: $out/demo.png"
"$build"/tools/pumptherm plot \
  --truth "$out/pump1.truth.csv" --estimate "$out/estimates/pump1.csv" --label "pump1" \
  --truth "$out/pump2.truth.csv" --estimate "$out/estimates/pump2.csv" --label "pump2" \
  --truth "$out/pump3.truth.csv" --estimate "$out/estimates/pump3.csv" --label "pump3 (cooling fails)" \
  --nodes winding,rotor,stator,frame --extra winding_resistance_C=winding,magnet_flux_C=rotor \
  --warning-C 100 --trip-C 120 --row-height 380 \
  --title "pumptherm demo: estimated (dashed, +-2 sd shaded) against true (solid) temperatures; points: winding from resistance, magnet from flux" \
  --out "$out/demo.png"
echo
echo "Done. The plot is $out/demo.png; estimates per pump in $out/estimates/, the gateway's"
echo "CAN output in $out/gateway.log (candump format), its LCM messages in $out/gateway.lcm."
