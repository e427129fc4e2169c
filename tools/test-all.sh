#!/usr/bin/env bash
# Builds pumptherm and runs every test layer: unit tests, the unit tests again under
# AddressSanitizer + UndefinedBehaviorSanitizer, short fuzz runs, and the vcan tests (natively
# where the kernel has vcan, otherwise in a QEMU guest). Ends with CTest's summary of the main
# build (unit + vcan). Run tools/setup.sh first (the README's command does).
#
# Environment: PUMPTHERM_JOBS (default: number of cores), PUMPTHERM_GUEST_JOBS (tests at a time in
# the last stage; default 1.5 x PUMPTHERM_JOBS), PUMPTHERM_FUZZ_SECONDS (default 60), CI=true
# makes a vcan test that can run neither natively nor in the guest fail, not skip.
set -euo pipefail
cd "$(dirname "$0")/.."
jobs=${PUMPTHERM_JOBS:-$(nproc)}
# The last stage's guests spend much of their time waiting on the wall clock (a recording replayed
# at its own pace, a restart awaited), so it runs more tests than there are cores: at one test a
# core the cores were 70 % busy, at 1.5 a core 89 % (docs/testing.md, "Time").
guest_jobs=${PUMPTHERM_GUEST_JOBS:-$((jobs + (jobs + 1) / 2))}
fuzz_seconds=${PUMPTHERM_FUZZ_SECONDS:-60}
start=$(date +%s)
stage() { printf '\n=== %s (%ds)\n' "$*" $(( $(date +%s) - start )); }

stage "format (.clang-format: clang-format 14, 100 columns)"
tools/format-check.sh

stage "build (warnings are errors)"
# -g1 (line tables): backtraces keep file:line, and the build takes a fifth less time than with
# full debug information (measured per file, docs/testing.md).
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DPUMPTHERM_WERROR=ON \
  "-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=-O2 -g1 -DNDEBUG" "-DCMAKE_C_FLAGS_RELWITHDEBINFO=-O2 -g1 -DNDEBUG"
cmake --build build -j "$jobs"

stage "unit tests"
ctest --test-dir build -L unit -j "$jobs" --output-on-failure

stage "unit tests under AddressSanitizer + UndefinedBehaviorSanitizer (clang; the same build has the fuzz targets)"
# One clang build for both: every source carries ASan + UBSan, and the libraries the fuzz targets
# link carry libFuzzer's coverage instrumentation too (cmake/PumpthermFlags.cmake), so the fuzz
# targets link the same libraries the sanitized unit tests use. -O1 -g1 (line tables only) with assertions on: the sanitizers' reports
# keep file:line. clang compiles our sources under the sanitizers about 40 % faster than GCC 12
# (measured per file, docs/testing.md), and one build instead of two saves the second one. One
# fixed-size Kalman path (6 states, the mismatch test's on every pump) instead of eight: the same
# template code, sanitized at one size; the other sizes take the dynamic path here (docs/testing.md).
CC=clang CXX=clang++ cmake -S . -B build-asan -G Ninja -DCMAKE_BUILD_TYPE=Debug \
  "-DCMAKE_CXX_FLAGS_DEBUG=-O1 -g1" "-DCMAKE_C_FLAGS_DEBUG=-O1 -g1" -DPUMPTHERM_WERROR=ON \
  -DPUMPTHERM_SANITIZE=ON -DPUMPTHERM_FUZZ=ON -DPUMPTHERM_BUILD_BENCHMARKS=OFF \
  -DPUMPTHERM_KALMAN_FIXED_FIRST=6 -DPUMPTHERM_KALMAN_FIXED_LAST=6
cmake --build build-asan -j "$jobs"
# Label long (docs/testing.md, "Labels"): long simulations that repeat what shorter cases run
# under the sanitizers; they ran in the unit stage above.
ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
  ctest --test-dir build-asan -L unit -LE long -j "$jobs" --output-on-failure

stage "fuzz targets, ${fuzz_seconds} s each"
tests/fuzz/run.sh build-asan "$fuzz_seconds"

stage "vcan tests (native vcan, or a QEMU guest), package checks, slow tests, system tests (Debian guest with systemd)"
# Verbose, so the log shows each test's mode line ("vcan: mode=guest kernel=...") and its
# scenario's output: proof that they ran rather than skipped. Unit tests ran above. The log is
# printed when CTest is done, so that CTest's summary line closes the output.
set +e
ctest --test-dir build -L 'vcan|system|package|slow' -j "$guest_jobs" -V >build/vcan-system-tests.log 2>&1
rc=$?
set -e
grep -vE '^[0-9]+: (Test command|Working Directory|Environment variables|Test timeout|UpdateCTestConfiguration)|^UpdateCTestConfiguration|^Parse Config|^ Add coverage|^Constructing a list|^Updating test list|^Checking test dependency|^test [0-9]+$|^ +Start [0-9]+:' \
  build/vcan-system-tests.log
exit $rc
