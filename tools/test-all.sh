#!/usr/bin/env bash
# Builds pumptherm and runs every test layer: unit tests, the unit tests again under
# AddressSanitizer + UndefinedBehaviorSanitizer, short fuzz runs, and the vcan tests (natively
# where the kernel has vcan, otherwise in a QEMU guest). Ends with CTest's summary of the main
# build (unit + vcan). Run tools/setup.sh first (the README's command does).
#
# Environment: PUMPTHERM_JOBS (default: number of cores), PUMPTHERM_FUZZ_SECONDS (default 60),
# CI=true makes a vcan test that can run neither natively nor in the guest fail, not skip.
set -euo pipefail
cd "$(dirname "$0")/.."
jobs=${PUMPTHERM_JOBS:-$(nproc)}
fuzz_seconds=${PUMPTHERM_FUZZ_SECONDS:-60}
start=$(date +%s)
stage() { printf '\n=== %s (%ds)\n' "$*" $(( $(date +%s) - start )); }

stage "build (warnings are errors)"
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DPUMPTHERM_WERROR=ON
cmake --build build -j "$jobs"

stage "unit tests"
ctest --test-dir build -L unit -j "$jobs" --output-on-failure

stage "unit tests under AddressSanitizer + UndefinedBehaviorSanitizer"
# -O1 -g1 (line tables only) with assertions on: GCC 12 compiles our sources under the sanitizers
# 3.5-7x slower at -O2 -g than at -O1 -g1 (measured per file, docs/testing.md), and -O1 keeps the
# tests fast enough; -g1 still gives file:line in the sanitizers' reports.
cmake -S . -B build-asan -G Ninja -DCMAKE_BUILD_TYPE=Debug "-DCMAKE_CXX_FLAGS_DEBUG=-O1 -g1" \
  "-DCMAKE_C_FLAGS_DEBUG=-O1 -g1" -DPUMPTHERM_WERROR=ON -DPUMPTHERM_SANITIZE=ON \
  -DPUMPTHERM_BUILD_BENCHMARKS=OFF
cmake --build build-asan -j "$jobs"
ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
  ctest --test-dir build-asan -L unit -j "$jobs" --output-on-failure

if [[ -x tests/fuzz/run.sh ]]; then
  stage "fuzz targets, ${fuzz_seconds} s each"
  CC=clang CXX=clang++ cmake -S . -B build-fuzz -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
    -DPUMPTHERM_FUZZ=ON -DPUMPTHERM_BUILD_BENCHMARKS=OFF
  cmake --build build-fuzz -j "$jobs" --target pumptherm_fuzz_all
  tests/fuzz/run.sh build-fuzz "$fuzz_seconds"
fi

stage "vcan tests (native vcan, or a QEMU guest), package checks, slow tests, system tests (Debian guest with systemd)"
# Verbose, so the log shows each test's mode line ("vcan: mode=guest kernel=...") and its
# scenario's output: proof that they ran rather than skipped. Unit tests ran above. The log is
# printed when CTest is done, so that CTest's summary line closes the output.
set +e
ctest --test-dir build -L 'vcan|system|package|slow' -j "$jobs" -V >build/vcan-system-tests.log 2>&1
rc=$?
set -e
grep -vE '^[0-9]+: (Test command|Working Directory|Environment variables|Test timeout|UpdateCTestConfiguration)|^UpdateCTestConfiguration|^Parse Config|^ Add coverage|^Constructing a list|^Updating test list|^Checking test dependency|^test [0-9]+$|^ +Start [0-9]+:' \
  build/vcan-system-tests.log
exit $rc
