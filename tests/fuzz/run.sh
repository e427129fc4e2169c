#!/usr/bin/env bash
# Runs every libFuzzer target of a fuzz build for SECONDS each, PUMPTHERM_FUZZ_JOBS (default 2)
# targets at a time; exits non-zero on a finding.
#
#   CXX=clang++ cmake -S . -B build-fuzz -G Ninja -DPUMPTHERM_FUZZ=ON -DPUMPTHERM_BUILD_BENCHMARKS=OFF
#   cmake --build build-fuzz --target pumptherm_fuzz_all
#   tests/fuzz/run.sh build-fuzz 30            # 8 targets, 2 at a time: about 4 x 30 s
#   tests/fuzz/run.sh build-fuzz 60 csv_reader_fuzz   # only the targets named
#
# Targets are the executables named *_fuzz under BUILD_DIR/tests/fuzz. Seed corpora: a target
# gets the files listed by seeds_for below (add a case for a new target); the working corpus
# and any crash artifacts go to BUILD_DIR/fuzz/<target>/.
set -euo pipefail

if [[ $# -lt 2 ]]; then
  echo "usage: $0 BUILD_DIR SECONDS [TARGET...]" >&2
  exit 2
fi
build=$(cd "$1" && pwd)
seconds=$2
shift 2
jobs=${PUMPTHERM_FUZZ_JOBS:-2}
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
shared="$root/../shared/data"
shared_dbc="$shared/dbc"

# Prints the seed files of a target, one per line.
seeds_for() {
  case "$1" in
    dbc_reader_fuzz)
      ls "$root"/protocol/*.dbc "$root"/tests/protocol/candied/*.dbc
      if [[ -d "$shared_dbc" ]]; then find "$shared_dbc" -name '*.dbc' | sort; fi
      ;;
    config_reader_fuzz)
      ls "$root"/systemd/*.toml "$root"/tools/demo/*.toml "$root"/tests/fuzz/seeds/config/*.toml
      ;;
    thermal_model_fuzz)
      ls "$root"/estimators/models/*.toml
      ;;
    motor_description_fuzz)
      ls "$root"/estimators/motors/*.toml
      ;;
    candump_log_fuzz | csv_reader_fuzz | pipeline_step_fuzz) ;;  # written by write_seeds
    *) ;;
  esac
}

# Seeds cut from large files (libFuzzer works best on small inputs) or generated.
write_seeds() {
  local name=$1 dir=$2 f
  case "$name" in
    candump_log_fuzz)
      head -n 40 "$root/tests/data/skeleton.log" > "$dir/skeleton_head.log"
      printf '(1436509052.249713) vcan0 044#2A366C2BBA\n(1436509052.449847) vcan0 1F334455#R\n(1436509052.649981) vcan0 123##1112233\n(0.000000) can0 7FF#R3\n# comment\n\n' > "$dir/forms.log"
      printf '  can0  123   [8]  11 22 33 44 55 66 77 88\n (1436509052.249713)  can0  RX B E  123  [12]  00 11 22 33 44 55 66 77 88 99 AA BB\n  can1       7FF   [4]  remote request\n  can0  20000004   [8]  00 04 00 00 00 00 00 00   ERRORFRAME\n(1795643917.565645) can0 044#2A366C2BBA R\n' > "$dir/screen_forms.log"
      ;;
    csv_reader_fuzz)
      if [[ -d "$shared/paderborn" ]]; then
        for f in "$shared"/paderborn/*.csv; do head -n 30 "$f" > "$dir/$(basename "$f")"; done
      fi
      printf 'time_s,iq_A,frame_C\n0,1.5,25\n0.1,,nan\n0.2,1e3,-4.5e-1\n' > "$dir/small.csv"
      ;;
    pipeline_step_fuzz)
      python3 "$root/tests/fuzz/make_pipeline_seeds.py" "$dir"
      ;;
    frame_decode_fuzz)
      write_frame_seeds "$dir"
      ;;
  esac
}

# Seeds that are byte strings rather than files: message selector byte + 8 or 64 payload bytes.
write_frame_seeds() {
  local dir=$1 i
  for i in 0 1 2 3 4 5 6 7 8 9 10; do
    printf "\\x$(printf %02x "$i")\\x12\\x34\\x56\\x78\\x9a\\xbc\\xde\\xf0" > "$dir/seed_$i"
    head -c 64 /dev/zero | tr '\0' '\377' | { printf "\\x$(printf %02x "$i")"; cat; } > "$dir/seed_ff_$i"
  done
}

shopt -s nullglob
if (($# > 0)); then
  targets=()
  for t in "$@"; do targets+=("$build/tests/fuzz/$t"); done
else
  targets=("$build"/tests/fuzz/*_fuzz)
fi
if ((${#targets[@]} == 0)); then
  echo "run.sh: no *_fuzz executables under $build/tests/fuzz (configure with -DPUMPTHERM_FUZZ=ON)" >&2
  exit 2
fi

# One target: seeds, run, verdict in $work/verdict (ok or finding), summary lines on stdout.
run_one() {
  local target=$1 name work f max_len
  name=$(basename "$target")
  work="$build/fuzz/$name"
  rm -rf "$work/seeds"
  mkdir -p "$work/corpus" "$work/seeds" "$work/artifacts"
  while IFS= read -r f; do
    [[ -n "$f" ]] && cp "$f" "$work/seeds/$(echo "$f" | tr '/' '_')"
  done < <(seeds_for "$name")
  write_seeds "$name" "$work/seeds"
  echo "run.sh: $name for ${seconds}s ($(ls "$work/seeds" | wc -l) seeds, $(ls "$work/corpus" | wc -l) in the corpus)"
  # Logging of the daemon code (alarms, clears) goes to the log file, not the terminal.
  # pipeline_step_fuzz: every frame runs the pipeline, so short inputs (a few seconds of
  # telemetry) keep it at hundreds of executions per second rather than a handful.
  max_len=65536
  [[ "$name" == pipeline_step_fuzz ]] && max_len=12288
  if ! PUMPTHERM_SOURCE_DIR="$root" "$target" -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 \
      -max_len="$max_len" -print_final_stats=1 -artifact_prefix="$work/artifacts/" \
      "$work/corpus" "$work/seeds" > "$work/log.txt" 2>&1; then
    echo finding > "$work/verdict"
    echo "run.sh: FINDING in $name (log $work/log.txt, artifacts $work/artifacts/):" >&2
    tail -n 40 "$work/log.txt" >&2
  else
    echo ok > "$work/verdict"
    { grep -E "^#[0-9]+[[:space:]]+DONE" "$work/log.txt" || true; } | tail -n 1 | sed "s/^/  $name /"
    { grep -E "stat::number_of_executed_units|stat::peak_rss_mb" "$work/log.txt" || true; } | sed "s/^/  $name /"
  fi
}

running=0
for target in "${targets[@]}"; do
  if [[ ! -x "$target" ]]; then
    echo "run.sh: no fuzz target $target" >&2
    exit 2
  fi
  rm -f "$build/fuzz/$(basename "$target")/verdict"
  if ((running >= jobs)); then
    wait -n || true
    running=$((running - 1))
  fi
  run_one "$target" &
  running=$((running + 1))
done
wait

status=0
for target in "${targets[@]}"; do
  name=$(basename "$target")
  if [[ "$(cat "$build/fuzz/$name/verdict" 2>/dev/null)" != ok ]]; then
    echo "run.sh: $name: no clean run" >&2
    status=1
  fi
done
exit $status
