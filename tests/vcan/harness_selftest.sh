#!/usr/bin/env bash
# shellcheck disable=SC2001,SC2030,SC2031 # sed on captured output; the CI/cache subshell is meant
# Checks that run_vcan_test.sh reports failures truthfully: bad arguments (exit 2), the skip/fail
# logic when no mode is possible (77, or 1 with CI=true), a scenario's exit code and output passed
# through, a guest that stops without a result, and a scenario that hangs past --timeout.
#
#   harness_selftest.sh CACHE_DIR
#
# The guest checks boot QEMU (three boots, one of them waits for a 40 s timeout); where no mode
# can run they are skipped (exit 77) unless CI=true.
set -uo pipefail

harness=$(dirname "$0")/run_vcan_test.sh
readonly harness
readonly cache=${1:?usage: harness_selftest.sh CACHE_DIR}
work=$(mktemp -d "${TMPDIR:-/tmp}/vcan-selftest.XXXXXX")
trap 'rm -rf "$work"' EXIT
failures=0

# check NAME WANT_RC PATTERN... -- HARNESS_ARGS...: runs the harness and checks its exit code and
# that every (extended) regular expression PATTERN matches a line of its combined output.
check() {
  local name=$1 want_rc=$2
  shift 2
  local patterns=()
  while (($#)) && [[ "$1" != "--" ]]; do patterns+=("$1"); shift; done
  shift
  local out rc=0 p ok=1
  out=$("$harness" "$@" 2>&1) || rc=$?
  # Failed runs keep their run directory for debugging; these failures are expected.
  local kept
  kept=$(sed -n 's/^vcan: run directory kept: //p' <<<"$out")
  [[ -z "$kept" ]] || rm -rf "$kept"
  [[ "$rc" == "$want_rc" ]] || ok=0
  for p in "${patterns[@]}"; do
    grep -Eq -- "$p" <<<"$out" || { ok=0; echo "selftest: $name: no line matches /$p/"; }
  done
  if ((ok)); then
    echo "selftest: ok: $name (exit $rc)"
  else
    echo "selftest: FAIL: $name: exit $rc (want $want_rc); its output:"
    sed 's/^/  | /' <<<"$out"
    failures=$((failures + 1))
  fi
}

printf 'echo "line one from the scenario"\necho "line two on stderr" >&2\nexit 3\n' >"$work/exit3.sh"
printf 'echo "powering off under the harness"\necho o >/proc/sysrq-trigger\nsleep 60\n' \
  >"$work/poweroff.sh"
printf 'echo "about to hang"\nsleep 1000\n' >"$work/hang.sh"

# Arguments: no guest is started.
check "missing --bin is exit 2 naming the path" 2 "--bin '$work/nonexistent' is not an executable" -- \
  --cache-dir "$cache" --bin "$work/nonexistent" "$work/exit3.sh"
check "bad --timeout is exit 2" 2 "--timeout: 'soon' is not" -- \
  --cache-dir "$cache" --timeout soon "$work/exit3.sh"
check "missing scenario is exit 2" 2 "scenario '$work/none.sh' is not a readable file" -- \
  --cache-dir "$cache" "$work/none.sh"

# No kernel: skip outside CI, fail in CI, with the reason either way.
(
  export PUMPTHERM_CACHE=$work/nokernel CI=false
  check "no guest kernel, not CI: skip (77) with the reason" 77 \
    "SKIP exit3: no guest kernel with its modules under $work/nokernel/kernel" -- \
    --cache-dir "$cache" --mode guest "$work/exit3.sh"
  export CI=true
  check "no guest kernel, CI=true: fail (1) with the reason" 1 \
    "cannot run exit3: no guest kernel .*CI=true" -- --cache-dir "$cache" --mode guest "$work/exit3.sh"
  exit "$failures"
)
failures=$((failures + $?))

# Is a guest possible here? Otherwise the rest cannot run.
kernel_ok=0
for v in "${PUMPTHERM_CACHE:-/var/cache/pumptherm}"/kernel/boot/vmlinuz-*; do [[ -r "$v" ]] && kernel_ok=1; done
if ((kernel_ok == 0)) || ! command -v qemu-system-x86_64 >/dev/null 2>&1; then
  if [[ "${CI:-}" == "true" ]]; then
    echo "selftest: FAIL: no guest kernel or no QEMU, and CI=true"
    exit 1
  fi
  echo "selftest: guest checks skipped: no guest kernel or no QEMU here (${failures} failures so far)"
  ((failures == 0)) && exit 77
  exit 1
fi

check "scenario exit code and output (stdout and stderr) passed through" 3 \
  "^vcan: mode=guest kernel=[^ ]+ test=exit3" "^line one from the scenario$" \
  "^line two on stderr$" "scenario exit code 3$" -- \
  --cache-dir "$cache" --mode guest "$work/exit3.sh"
check "guest that stops without a result: exit 1, says so, shows its console" 1 \
  "^powering off under the harness$" "poweroff: the guest stopped without reporting a result" \
  "^---- guest console" -- --cache-dir "$cache" --mode guest "$work/poweroff.sh"
check "scenario hanging past --timeout: exit 1, says so" 1 "no result from the guest within 40 s" -- \
  --cache-dir "$cache" --mode guest --timeout 40 "$work/hang.sh"

if ((failures)); then
  echo "selftest: ${failures} check(s) failed"
  exit 1
fi
echo "selftest: PASS"
