# shellcheck shell=bash disable=SC2154 # kMarker, name, run_dir and the rest are set by the harness
# The host side of the QEMU guest tests, shared by tests/vcan/run_vcan_test.sh and
# tests/system/run_system_test.sh (sourced by both; bash): the guest kernel, and the protocol.
#
# The guest writes its result to its second serial port (a file on the host), one line each:
#   <MARKER>-BEGIN <text>@@         the scenario starts (text: what the guest says about itself)
#   <MARKER>-SETUP-FAILED <why>@@   the guest could not set the scenario up
#   <MARKER>-OUT-BEGIN@@ ... <MARKER>-OUT-END@@   the scenario's OUT_DIR as base64 of a .tar.gz
#   <MARKER>-EXIT <code>@@          the scenario's exit code; the guest powers off after it
# Every other line after BEGIN is the scenario's output. The first serial port is the console.
#
# The harness defines before calling: kMarker, name, out_dir, timeout_s, verbose, keep, run_dir,
# say and err (its message prefixes), and guest_on_begin TEXT (what the BEGIN marker means to it).

# The absolute path of FILE (its directory must exist).
abspath() { (cd "$(dirname "$1")" && printf '%s/%s\n' "$(pwd -P)" "$(basename "$1")"); }
now_s() { date +%s.%N; }
# Seconds since START_S (a now_s value), to 0.1 s.
elapsed_s() { awk -v a="$1" -v b="$(now_s)" 'BEGIN { printf "%.1f", b - a }'; }

# Sets kernel_root (<cache>/kernel) and kernel_version (the newest vmlinuz-<ver> that has its
# modules), or ends the run with the harness's cannot_run.
find_kernel() {
  kernel_root=${PUMPTHERM_CACHE:-/var/cache/pumptherm}/kernel
  local v
  kernel_version=$(for v in "$kernel_root"/boot/vmlinuz-*; do
    v=${v##*/vmlinuz-}
    if [[ -r "$kernel_root/boot/vmlinuz-$v" && -d "$kernel_root/lib/modules/$v/kernel" ]]; then
      echo "$v"
    fi
  done | sort -V | tail -n 1)
  [[ -n "$kernel_version" ]] ||
    cannot_run "no guest kernel with its modules under $kernel_root (run tools/setup.sh)"
}

# Seconds between two looks at the result port while the guest runs.
readonly kGuestPoll_s=0.2
# Lines of the console shown when a run fails.
readonly kGuestConsoleLines=200

# guest_print_console CONSOLE: its last lines on stderr, carriage returns and escape sequences removed.
guest_print_console() {
  local console=$1
  if [[ -s "$console" ]]; then
    echo "---- guest console (last $kGuestConsoleLines lines of $console) ----" >&2
    tail -n "$kGuestConsoleLines" "$console" | tr -d '\r' | sed 's/\x1b\[[0-9;]*[A-Za-z]//g' >&2
    echo "---- end of guest console ----" >&2
  else
    echo "(the guest console is empty: $console)" >&2
  fi
}

# guest_stream RESULT CONSOLE: prints what the guest wrote to RESULT since the last call (and, with
# verbose, to CONSOLE) and follows the markers. State in guest_* variables (guest_watch sets them).
guest_stream() {
  local result=$1 console=$2 total line
  total=$(wc -l <"$result")
  if ((total > guest_printed)); then
    while IFS= read -r line; do
      line=${line%$'\r'}
      case "$guest_state:$line" in
        *"$kMarker-BEGIN "*)
          guest_begin_s=$(elapsed_s "$guest_start")
          local what=${line#*BEGIN }
          guest_on_begin "${what%@@}"
          guest_state=run ;;
        *"$kMarker-SETUP-FAILED "*)
          guest_setup_failure=${line#*FAILED }
          guest_setup_failure=${guest_setup_failure%@@} ;;
        *"$kMarker-OUT-BEGIN@@"*)
          # A last scenario line without its newline shares the line with the marker.
          [[ "$line" == "$kMarker"* ]] || printf '%s\n' "${line%%"$kMarker"*}"
          guest_state=out
          : >"$guest_out_b64" ;;
        *"$kMarker-OUT-END@@"*) guest_state=run ;;
        *"$kMarker-EXIT "*)
          [[ "$guest_state" != run || "$line" == "$kMarker"* ]] || printf '%s\n' "${line%%"$kMarker"*}"
          guest_exit_code=${line#*EXIT }
          guest_exit_code=${guest_exit_code%@@}
          [[ "$guest_exit_code" =~ ^[0-9]+$ ]] || { err "garbled exit marker: $line"; guest_exit_code=1; } ;;
        out:*) printf '%s\n' "$line" >>"$guest_out_b64" ;;
        run:*)
          printf '%s\n' "$line"
          [[ "$line" != *": FAIL: "* ]] || guest_fail_lines+=("$line") ;;
        *) printf 'guest: %s\n' "$line" ;;
      esac
    done < <(sed -n "$((guest_printed + 1)),${total}p" "$result")
    guest_printed=$total
  fi
  if ((verbose)); then
    total=$(wc -l <"$console")
    if ((total > guest_console_printed)); then
      sed -n "$((guest_console_printed + 1)),${total}p" "$console" | tr -d '\r' | sed 's/^/console| /'
      guest_console_printed=$total
    fi
  fi
}

# guest_watch QEMU_PID START_S CONSOLE RESULT: streams the guest's output until its EXIT or
# SETUP-FAILED marker, QEMU's end, or timeout_s after START_S; then gives the guest a moment to
# power off and stops QEMU. Sets guest_exit_code, guest_setup_failure, guest_timed_out,
# guest_begin_s (empty when BEGIN never came), guest_fail_lines (the scenario's "NAME: FAIL: why").
guest_watch() {
  local qemu_pid=$1 console=$3 result=$4 deadline
  guest_start=$2
  guest_printed=0 guest_console_printed=0 guest_state=pre guest_exit_code="" guest_setup_failure=""
  guest_timed_out=0 guest_begin_s="" guest_out_b64=$run_dir/out.b64
  guest_fail_lines=()
  deadline=$(awk -v s="$guest_start" -v t="$timeout_s" 'BEGIN { printf "%d", s + t }')
  while :; do
    guest_stream "$result" "$console"
    [[ -n "$guest_exit_code" || -n "$guest_setup_failure" ]] && break
    if ! kill -0 "$qemu_pid" 2>/dev/null; then
      guest_stream "$result" "$console"
      break
    fi
    if (($(date +%s) >= deadline)); then
      guest_timed_out=1
      break
    fi
    sleep "$kGuestPoll_s"
  done
  # The guest powers off right after the marker; give it a moment, then make sure.
  local i
  for ((i = 0; i < 50 && !guest_timed_out; i++)); do kill -0 "$qemu_pid" 2>/dev/null || break; sleep 0.1; done
  kill "$qemu_pid" 2>/dev/null || true
  wait "$qemu_pid" 2>/dev/null || true
}

# guest_verdict CONSOLE: after guest_watch, says how the run ended, unpacks OUT_DIR, shows the
# console of a failed run, keeps or removes run_dir, repeats the scenario's FAIL lines of a failed
# run (so that a log cut to its tail still says why), and exits with the scenario's exit code
# (1 for a run without one; 77, a skip, is passed on).
guest_verdict() {
  local console=$1 took rc
  took=$(elapsed_s "$guest_start")
  if [[ -n "$guest_exit_code" ]]; then
    rc=$guest_exit_code
    if [[ -n "$out_dir" && -s "$guest_out_b64" ]]; then
      base64 -d "$guest_out_b64" | tar -xzf - -C "$out_dir" ||
        { err "${name}: could not unpack the guest's OUT_DIR into $out_dir"; rc=1; }
    fi
    say "guest run took ${took} s (boot ${guest_begin_s:-?} s, then the scenario and power-off), scenario exit code ${rc}"
  elif [[ -n "$guest_setup_failure" ]]; then
    err "${name}: guest setup failed: ${guest_setup_failure}"
    rc=1
  elif ((guest_timed_out)); then
    local what="the scenario did not finish"
    [[ -n "$guest_begin_s" ]] || what="the guest did not finish booting"
    err "${name}: no result from the guest within ${timeout_s} s (${what}); killed QEMU"
    rc=1
  else
    err "${name}: the guest stopped without reporting a result (boot failure or crash) after ${took} s"
    [[ -s "$run_dir/qemu.log" ]] && { echo "QEMU said:" >&2; cat "$run_dir/qemu.log" >&2; }
    rc=1
  fi
  if ((rc != 0 && rc != 77 && !verbose)); then guest_print_console "$console"; fi
  if ((keep || (rc != 0 && rc != 77))); then
    say "run directory kept: $run_dir"
  else
    rm -rf "$run_dir"
  fi
  if ((rc != 0 && rc != 77)); then
    local l
    for l in "${guest_fail_lines[@]}"; do say "${name} failed: ${l}"; done
  fi
  exit "$rc"
}
