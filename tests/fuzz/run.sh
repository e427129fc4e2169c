#!/usr/bin/env bash
# Runs every libFuzzer target of a fuzz build for SECONDS each; exits non-zero on a finding.
#
#   CXX=clang++ cmake -S . -B build-fuzz -G Ninja -DPUMPTHERM_FUZZ=ON -DPUMPTHERM_BUILD_BENCHMARKS=OFF
#   cmake --build build-fuzz --target dbc_reader_fuzz frame_decode_fuzz
#   tests/fuzz/run.sh build-fuzz 30
#
# Targets are the executables named *_fuzz under BUILD_DIR/tests/fuzz. Seed corpora: a target
# gets the files listed by seeds_for below (add a case for a new target); the working corpus
# and any crash artifacts go to BUILD_DIR/fuzz/<target>/.
set -euo pipefail

if [[ $# -ne 2 ]]; then
  echo "usage: $0 BUILD_DIR SECONDS" >&2
  exit 2
fi
build=$(cd "$1" && pwd)
seconds=$2
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
shared_dbc="$root/../shared/data/dbc"

# Prints the seed files of a target, one per line.
seeds_for() {
  case "$1" in
    dbc_reader_fuzz)
      ls "$root"/protocol/*.dbc "$root"/tests/protocol/candied/*.dbc
      if [[ -d "$shared_dbc" ]]; then find "$shared_dbc" -name '*.dbc' | sort; fi
      ;;
    *) ;;
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
targets=("$build"/tests/fuzz/*_fuzz)
if ((${#targets[@]} == 0)); then
  echo "run.sh: no *_fuzz executables under $build/tests/fuzz (configure with -DPUMPTHERM_FUZZ=ON)" >&2
  exit 2
fi

status=0
for target in "${targets[@]}"; do
  name=$(basename "$target")
  work="$build/fuzz/$name"
  mkdir -p "$work/corpus" "$work/seeds" "$work/artifacts"
  while IFS= read -r f; do
    [[ -n "$f" ]] && cp "$f" "$work/seeds/$(echo "$f" | tr '/' '_')"
  done < <(seeds_for "$name")
  [[ "$name" == frame_decode_fuzz ]] && write_frame_seeds "$work/seeds"
  echo "run.sh: $name for ${seconds}s ($(ls "$work/seeds" | wc -l) seeds)"
  if ! PUMPTHERM_SOURCE_DIR="$root" "$target" -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 \
      -max_len=65536 -print_final_stats=1 -artifact_prefix="$work/artifacts/" \
      "$work/corpus" "$work/seeds" > "$work/log.txt" 2>&1; then
    echo "run.sh: FINDING in $name (log $work/log.txt, artifacts $work/artifacts/):" >&2
    tail -n 40 "$work/log.txt" >&2
    status=1
  else
    grep -E "stat::number_of_executed_units|stat::peak_rss_mb" "$work/log.txt" | sed "s/^/  $name /"
  fi
done
exit $status
