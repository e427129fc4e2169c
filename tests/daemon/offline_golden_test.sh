#!/usr/bin/env bash
# Golden-file test of the offline pipeline (`pumpthermd -r`): everything a run writes - the CAN
# output log (--output-log), the LCM log (--lcm-log), the per-pump CSV (--csv-dir), stdout (the
# counts and the pump table) and stderr (the alarm and warning lines) - byte for byte against
# the SHA-256 sums in offline_golden.sha256. Two runs:
#   demo:   the demo recording (3 pumps, 20 min; pump3 warns, then trips), with a fourth pump
#           configured that is never heard from (stale telemetry raised on silence);
#   matrix: the first 240 s of the alarm-matrix recording (failed sensors, outages, a fast
#           rise, a lossy link), its stamps set back 30 s at the middle (a clock step).
# Any change of the pipeline's scheduling, reader or output path that changes a byte fails here;
# a deliberate change of the outputs regenerates the sums with --update (and says why in the
# commit). Usage: offline_golden_test.sh PUMPTHERMD PUMPTHERM SRC_DIR DEMO_LOG [--update]
# (KEEP_TMP=1 keeps the outputs and names their directory on stderr)
set -euo pipefail
pumpthermd=$1
pumptherm=$2
src=$3
demo_log=$4
update=${5:-}
sums=$src/tests/daemon/offline_golden.sha256
tmp=$(mktemp -d)
if [[ -n ${KEEP_TMP:-} ]]; then echo "kept: $tmp" >&2; else trap 'rm -rf "$tmp"' EXIT; fi
[[ -s $demo_log ]] || { echo "FAIL: $demo_log missing (built by vcan_pipeline_recording)"; exit 1; }

# run NAME CONFIG LOG: pumpthermd -r LOG with every output, in $tmp/NAME, relative names only
# (the outputs name their files).
run() {
  local name=$1 config=$2 log=$3
  mkdir -p "$tmp/$name"
  cp "$config" "$tmp/$name/config.toml"
  ln -s "$log" "$tmp/$name/in.log"
  local origin
  origin=$(head -n 1 "$log" | sed 's/^(\([0-9]*\)\..*/\1/')
  (cd "$tmp/$name" && env -u JOURNAL_STREAM TZ=UTC "$pumpthermd" --config config.toml -r in.log \
     --output-log out.log --lcm-log out.lcm --csv-dir csv --csv-time-origin "$origin" \
     >stdout.txt 2>stderr.txt) || { echo "FAIL: pumpthermd on $name:"; cat "$tmp/$name/stderr.txt"; exit 1; }
  rm "$tmp/$name/config.toml" "$tmp/$name/in.log"
}

{
  cat "$src/tools/demo/pumpthermd-demo.toml"
  printf '\n[[pump]]\nname = "ghost"\nnode_id = 9\nmotor = "han2019-tmp"\n'
  printf 'thermal_model = "tmp-generic"\nmeasured_node = "frame"\n'
} >"$tmp/demo.toml"
run demo "$tmp/demo.toml" "$demo_log"

"$pumptherm" plant "$src/tools/plant/scenarios/alarm-matrix.toml" --duration-s 240 --out "$tmp/plant" --quiet
awk 'NR == 1 { n = 0 } { lines[++n] = $0 } END {
  for (i = 1; i <= n; i++) {
    if (i > n / 2 && match(lines[i], /^\([0-9]+/)) {
      s = substr(lines[i], 2, RLENGTH - 1) - 30
      lines[i] = "(" s substr(lines[i], RLENGTH + 1)
    }
    print lines[i]
  } }' "$tmp/plant/alarm-matrix.log" >"$tmp/matrix.log"
run matrix "$src/tests/daemon/alarm_matrix.toml" "$tmp/matrix.log"

(cd "$tmp" && find demo matrix -type f | LC_ALL=C sort | xargs sha256sum) >"$tmp/got.sha256"
if [[ $update == --update ]]; then
  cp "$tmp/got.sha256" "$sums"
  echo "wrote $sums:"; cat "$sums"; exit 0
fi
if ! diff -u "$sums" "$tmp/got.sha256"; then
  echo "FAIL: the offline outputs differ from the golden sums above (- golden, + this build);"
  echo "      KEEP_TMP=1 keeps them; a deliberate change regenerates the sums with --update"
  exit 1
fi
echo "offline outputs equal the golden sums: $(wc -l <"$sums") files"
