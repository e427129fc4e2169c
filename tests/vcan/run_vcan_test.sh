#!/usr/bin/env bash
# Runs one vcan test scenario: a POSIX sh script that finds vcan0 up, can-utils and iproute2's `ip`
# on PATH, the binaries under test in $BIN_DIR, data files in $DATA_DIR and a writable $WORK_DIR.
#
# Mode "native": the host kernel has vcan; the scenario runs in a fresh network namespace of its
# own (its own vcan0 and loopback), or on the host's existing vcan0 when no namespace can be made
# (mode "host" asks for the latter).
# Mode "guest": the host kernel has no CAN; the scenario runs in a QEMU guest (TCG) booted from
# Debian's kernel (unpacked by tools/setup.sh under $PUMPTHERM_CACHE, default
# /var/cache/pumptherm) with an initramfs holding busybox, the CAN modules, can-utils, ip, the
# binaries with their shared libraries, the data files and the scenario. The scenario's output
# comes back over a second serial port; kernel messages stay on the first one and are shown only
# when the run fails (or with --verbose).
#
# Exit status: the scenario's own status; 1 when the harness fails (guest never reports, timeout);
# 77 when no mode is possible and CI is not "true" (CTest's SKIP_RETURN_CODE). With CI=true a run
# that is impossible fails with the reason instead.
#
# Documentation: docs/testing-vcan.md.
set -euo pipefail

readonly kHarnessVersion=1
readonly kMarker="@@PUMPTHERM-VCAN"
# The host side of the guest protocol (markers, streaming, verdict), shared with the other harness.
# shellcheck source-path=SCRIPTDIR source=../guest/guest_run.sh
source "$(dirname "${BASH_SOURCE[0]}")/../guest/guest_run.sh"
readonly kCanUtils=(candump cansend canplayer cangen cansequence canbusload cansniffer canfdtest
  cangw log2asc log2long asc2log)
# Host programs the guest gets in place of busybox applets. Debian's busybox-static prefers its own
# applets to PATH (in its sh and in anything it execs), so its `ip` would shadow iproute2's: the
# scenario runs under dash (Debian's /bin/sh, as natively), and the usual exec wrappers are the
# real ones, so `timeout 5 ip ...` runs iproute2's ip too.
readonly kHostTools=(dash timeout env nohup xargs setsid)
# Inserted in this order: vcan.ko needs can-dev.ko, can-raw.ko needs can.ko.
readonly kModules=(net/can/can net/can/can-raw drivers/net/can/dev/can-dev drivers/net/can/vcan)

usage() {
  cat <<'EOF'
usage: run_vcan_test.sh [options] SCENARIO

Runs SCENARIO (a POSIX sh script) with vcan0 up, natively or in a QEMU guest.

options:
  --bin PATH        a binary under test, put in $BIN_DIR with its shared libraries (repeatable)
  --file PATH       a data file or directory, put in $DATA_DIR (repeatable)
  --timeout S       give up after S seconds (default $PUMPTHERM_VCAN_TIMEOUT or 300)
  --mode M          auto | native | host | guest (default $PUMPTHERM_VCAN_MODE or auto):
                    native = a network namespace with its own vcan0, else the host's vcan0;
                    host = the host's existing vcan0 only (e.g. to watch it with candump)
  --cache-dir DIR   where the guest's base initramfs is cached and runs are staged
                    (default $PUMPTHERM_VCAN_CACHE or ~/.cache/pumptherm-vcan)
  --out-dir DIR     copy the files the scenario wrote under $OUT_DIR back to DIR
  --name NAME       test name used in messages (default: the scenario's file name)
  --verbose         also stream the guest's console (kernel messages)
  --keep            keep the run directory (initramfs, console logs) even on success
  --shell           guest only, interactive: run the scenario on the console, then open a shell
                    in the guest (leave with `poweroff -f`)
  -h, --help        this text

environment:
  PUMPTHERM_CACHE   where tools/setup.sh unpacked the guest kernel (default /var/cache/pumptherm)
  PUMPTHERM_VCAN_VERBOSE=1, PUMPTHERM_VCAN_KEEP=1   as --verbose and --keep (e.g. under ctest)
  PUMPTHERM_VCAN_PVH=0   boot the compressed vmlinuz, not the cached uncompressed vmlinux
  PUMPTHERM_VCAN_SMP=N   give the guest N emulated CPUs (default 1; QEMU runs each on its own
                         host thread, so N > 1 only helps with idle host cores)
  CI=true           a run that is possible neither way fails instead of skipping (exit 77)

example:
  tests/vcan/run_vcan_test.sh --bin build/daemon/pumpthermd --file tests/data/x.log \
      tests/vcan/smoke.sh
EOF
}

say() { printf 'vcan: %s\n' "$*"; }
err() { printf 'vcan: error: %s\n' "$*" >&2; }

# A run that is impossible here: skip (77), or fail under CI=true.
cannot_run() {
  if [[ "${CI:-}" == "true" ]]; then
    err "cannot run ${name}: $* (CI=true: vcan tests must run, not skip)"
    exit 1
  fi
  say "SKIP ${name}: $*"
  exit 77
}

bins=()
files=()
timeout_s=${PUMPTHERM_VCAN_TIMEOUT:-300}
mode=${PUMPTHERM_VCAN_MODE:-auto}
cache_dir=${PUMPTHERM_VCAN_CACHE:-${XDG_CACHE_HOME:-${HOME:-/tmp}/.cache}/pumptherm-vcan}
out_dir=""
name=""
verbose=${PUMPTHERM_VCAN_VERBOSE:-0}
keep=${PUMPTHERM_VCAN_KEEP:-0}
shell=0
scenario=""

while (($#)); do
  case "$1" in
    --bin) bins+=("${2:?--bin needs a path}"); shift 2 ;;
    --file) files+=("${2:?--file needs a path}"); shift 2 ;;
    --timeout) timeout_s=${2:?--timeout needs seconds}; shift 2 ;;
    --mode) mode=${2:?--mode needs auto, native or guest}; shift 2 ;;
    --cache-dir) cache_dir=${2:?--cache-dir needs a directory}; shift 2 ;;
    --out-dir) out_dir=${2:?--out-dir needs a directory}; shift 2 ;;
    --name) name=${2:?--name needs a name}; shift 2 ;;
    --verbose) verbose=1; shift ;;
    --keep) keep=1; shift ;;
    --shell) shell=1; shift ;;
    -h | --help) usage; exit 0 ;;
    --) shift; scenario=${1:-}; shift || true; break ;;
    -*) err "unknown option '$1' (see --help)"; exit 2 ;;
    *) scenario=$1; shift; break ;;
  esac
done
if (($#)); then err "unexpected argument '$1' after the scenario"; exit 2; fi
if [[ -z "$scenario" ]]; then err "no SCENARIO given (see --help)"; exit 2; fi
[[ -n "$name" ]] || name=$(basename "$scenario" .sh)
if [[ ! "$timeout_s" =~ ^[1-9][0-9]*$ ]]; then
  err "--timeout: '$timeout_s' is not a positive whole number of seconds"; exit 2
fi
case "$mode" in
  auto | native | host | guest) ;;
  *) err "--mode: '$mode' is not auto, native, host or guest"; exit 2 ;;
esac
if [[ ! -r "$scenario" ]]; then err "scenario '$scenario' is not a readable file"; exit 2; fi
for b in "${bins[@]}"; do
  if [[ ! -f "$b" || ! -x "$b" ]]; then err "--bin '$b' is not an executable file"; exit 2; fi
done
for f in "${files[@]}"; do
  if [[ ! -r "$f" ]]; then err "--file '$f' is not readable"; exit 2; fi
done
if ((shell)) && [[ "$mode" == "native" || "$mode" == "host" ]]; then err "--shell needs the guest mode"; exit 2; fi

scenario=$(abspath "$scenario")
for i in "${!bins[@]}"; do bins[i]=$(abspath "${bins[i]}"); done
for i in "${!files[@]}"; do files[i]=$(abspath "${files[i]}"); done
[[ -z "$out_dir" ]] || { mkdir -p "$out_dir" && out_dir=$(cd "$out_dir" && pwd -P); }


# ---------------------------------------------------------------------------------------------
# Native mode
# ---------------------------------------------------------------------------------------------

# Commands run as root in a fresh network namespace before the scenario (also LCM's multicast
# route, so that udpm:// traffic stays on this namespace's loopback).
readonly kNamespaceSetup='ip link add dev vcan0 type vcan && ip link set vcan0 up &&
ip link set lo up && ip link set lo multicast on && ip route add 224.0.0.0/4 dev lo'

# Runs the scenario ($0) in a session of its own and, when it exits (or we are terminated), ends
# whatever it left running in that session, as the guest does.
# shellcheck disable=SC2016 # expanded by the child shell
readonly kNativeRun='cd "$WORK_DIR" || exit 1
setsid sh "$0" </dev/null &
pid=$!
trap '"'"'kill -TERM -$pid 2>/dev/null; sleep 1; kill -KILL -$pid 2>/dev/null; exit 143'"'"' TERM INT
wait "$pid"
rc=$?
kill -TERM -$pid 2>/dev/null && sleep 0.2
kill -KILL -$pid 2>/dev/null
exit $rc'

# Prints how native mode can run here: "netns" (a namespace of our own), "host" (the host's
# vcan0, already present) or nothing.
native_kind() {
  local unshare_args=(--net)
  ((EUID == 0)) || unshare_args+=(--map-root-user)
  if [[ "$mode" != "host" ]] && command -v unshare >/dev/null 2>&1 && command -v ip >/dev/null 2>&1 &&
    unshare "${unshare_args[@]}" sh -c 'ip link add dev vcan0 type vcan' >/dev/null 2>&1; then
    echo netns
  elif command -v ip >/dev/null 2>&1 && ip link show dev vcan0 >/dev/null 2>&1; then
    echo host
  fi
}

run_native() {
  local kind=$1
  local work
  work=$(mktemp -d "${TMPDIR:-/tmp}/pumptherm-vcan-${name}.XXXXXX")
  mkdir -p "$work/bin" "$work/data" "$work/work"
  local b f
  for b in "${bins[@]}"; do ln -s "$b" "$work/bin/$(basename "$b")"; done
  for f in "${files[@]}"; do ln -s "$f" "$work/data/$(basename "$f")"; done
  local out=${out_dir:-$work/out}
  mkdir -p "$out"
  if [[ "$kind" == "host" ]]; then
    ip link set dev vcan0 up 2>/dev/null || true
    if ! ip link show dev vcan0 | grep -q '[<,]UP[,>]'; then
      rm -rf "$work"
      cannot_run "the host's vcan0 exists but is down and cannot be brought up (not root?)"
    fi
  fi
  say "mode=native (${kind}) kernel=$(uname -r) test=${name}"
  local start
  start=$(now_s)
  local cmd=(sh -c "${kNativeRun}" "$scenario")
  if [[ "$kind" == "netns" ]]; then
    local unshare_args=(--net)
    ((EUID == 0)) || unshare_args+=(--map-root-user)
    cmd=(unshare "${unshare_args[@]}" sh -c "${kNamespaceSetup} || exit 1
${kNativeRun}" "$scenario")
  fi
  local rc=0
  env PATH="$work/bin:$PATH" BIN_DIR="$work/bin" DATA_DIR="$work/data" WORK_DIR="$work/work" \
    OUT_DIR="$out" VCAN_MODE=native \
    timeout --kill-after=10 "$timeout_s" "${cmd[@]}" 2>&1 || rc=$?
  if ((rc == 124 || rc == 137)); then
    err "${name}: the scenario did not finish within ${timeout_s} s"
    rc=1
  fi
  say "native run took $(elapsed_s "$start") s, scenario exit code ${rc}"
  if ((keep)); then say "run directory kept: $work"; else rm -rf "$work"; fi
  exit "$rc"
}

# ---------------------------------------------------------------------------------------------
# Guest mode
# ---------------------------------------------------------------------------------------------

# The guest's /init (busybox sh). Reads /opt/run.conf (written per run).
guest_init() {
  cat <<'EOF'
#!/bin/busybox sh
# PID 1 of the vcan test guest (written by tests/vcan/run_vcan_test.sh). busybox sh runs applets
# before PATH, so iproute2's ip and the scenario's shell are called by full path.
export PATH=/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin HOME=/root
mount -t proc proc /proc
mount -t sysfs sysfs /sys
mount -t devtmpfs devtmpfs /dev
mkdir -p /dev/pts /dev/shm
mount -t devpts devpts /dev/pts
mount -t tmpfs tmpfs /dev/shm
mount -t tmpfs tmpfs /tmp
mount -t tmpfs tmpfs /run
# Keep kernel messages off the console from here on; boot errors before this still show.
dmesg -n 1
. /opt/run.conf
out=/dev/ttyS1
[ "$SHELL_MODE" = 1 ] && out=/dev/console
stty -F "$out" raw -echo 2>/dev/null
say() { echo "pumptherm-vcan-init: $*"; }
setup_failed() {
  say "setup failed: $*"
  echo "@@PUMPTHERM-VCAN-SETUP-FAILED $*@@" >"$out"
  poweroff -f
}
kver=$(uname -r)
for m in __MODULES__; do
  insmod "/lib/modules/$kver/$m.ko" || setup_failed "insmod $m.ko"
done
ip=/usr/sbin/ip
$ip link add dev vcan0 type vcan || setup_failed "ip link add dev vcan0 type vcan"
$ip link set vcan0 up || setup_failed "ip link set vcan0 up"
$ip link set lo up && $ip link set lo multicast on && $ip route add 224.0.0.0/4 dev lo ||
  setup_failed "loopback with a multicast route"
export BIN_DIR=/opt/bin DATA_DIR=/opt/data WORK_DIR=/tmp/work OUT_DIR=/tmp/out VCAN_MODE=guest
export PATH="$BIN_DIR:$PATH"
mkdir -p "$WORK_DIR" "$OUT_DIR"
say "vcan0 and lo are up; running the scenario of test $TEST_NAME"
echo "@@PUMPTHERM-VCAN-BEGIN kernel=$kver@@" >"$out"
(cd "$WORK_DIR" && exec /bin/sh /opt/scenario.sh) </dev/null >"$out" 2>&1
rc=$?
say "the scenario exited with code $rc"
# Whatever the scenario left running goes now, so that the marker below is the last writer and
# closing the port waits until every byte has left the guest.
kill -9 -1 2>/dev/null
sleep 0.1
if [ "$COLLECT_OUT" = 1 ]; then
  {
    echo "@@PUMPTHERM-VCAN-OUT-BEGIN@@"
    tar -C "$OUT_DIR" -cf - . | gzip -1 | base64
    echo "@@PUMPTHERM-VCAN-OUT-END@@"
  } >"$out"
fi
echo "@@PUMPTHERM-VCAN-EXIT $rc@@" >"$out"
if [ "$SHELL_MODE" = 1 ]; then
  say "scenario exit code $rc; shell in the guest, leave with: poweroff -f"
  # An interactive busybox sh reads $ENV: there, `ip` is iproute2's too.
  echo 'ip() { /usr/sbin/ip "$@"; }' >/root/.shrc
  cd "$WORK_DIR" && ENV=/root/.shrc setsid cttyhack /bin/busybox sh
fi
poweroff -f
EOF
}


# Sets guest_kernel_image: the uncompressed vmlinux (cached), which QEMU boots through its PVH
# entry point, or the compressed vmlinuz when that cannot be had. Under TCG, decompressing the
# kernel costs more than the rest of the boot (see docs/testing-vcan.md); PUMPTHERM_VCAN_PVH=0
# always boots the vmlinuz.
prepare_kernel_image() {
  local vmlinuz=$kernel_root/boot/vmlinuz-$kernel_version
  guest_kernel_image=$vmlinuz
  [[ "${PUMPTHERM_VCAN_PVH:-1}" != 0 ]] || return 0
  command -v readelf >/dev/null 2>&1 || return 0
  local key
  key=$(stat -L -c '%n %s %Y' "$vmlinuz" | sha256sum | cut -c1-16)
  local vmlinux=$cache_dir/vmlinux-$kernel_version-$key
  if [[ ! -s "$vmlinux" ]]; then
    (
      flock 9
      [[ -s "$vmlinux" ]] && exit 0
      local tmp=$vmlinux.tmp.$$ magic off tool notes
      trap 'rm -f "$tmp"' EXIT
      # The payload of a bzImage is a compressed ELF vmlinux: find the first stream that is one.
      for magic in xz gzip zstd; do
        case $magic in
          xz) off=$(LC_ALL=C grep -abo $'\xfd7zXZ\x00' "$vmlinuz" | head -n 1); tool=(xz -dc --single-stream) ;;
          gzip) off=$(LC_ALL=C grep -abo $'\x1f\x8b\x08' "$vmlinuz" | head -n 1); tool=(gzip -dc) ;;
          zstd) off=$(LC_ALL=C grep -abo $'\x28\xb5\x2f\xfd' "$vmlinuz" | head -n 1); tool=(zstd -qdc) ;;
        esac
        [[ -n "$off" ]] || continue
        command -v "${tool[0]}" >/dev/null 2>&1 || continue
        tail -c +$((${off%%:*} + 1)) "$vmlinuz" | "${tool[@]}" >"$tmp" 2>/dev/null || true
        # An ELF with the PVH entry note (XEN_ELFNOTE_PHYS32_ENTRY, type 0x12).
        notes=$(readelf -n "$tmp" 2>/dev/null || true)
        if [[ "$(head -c 4 "$tmp")" == $'\x7fELF' && "$notes" == *"(0x00000012)"* ]]; then
          mv "$tmp" "$vmlinux"
          find "$cache_dir" -maxdepth 1 -name 'vmlinux-*' ! -path "$vmlinux" -delete
          exit 0
        fi
      done
      exit 0
    ) 9>"$cache_dir/.lock"
  fi
  [[ -s "$vmlinux" ]] && guest_kernel_image=$vmlinux
  return 0
}

# Copies an executable and every shared library it needs (ldd) into the staging root $1, at the
# same absolute paths, so the dynamic loader and any RPATH find them.
stage_libraries() {
  local root=$1 exe=$2 lib
  # ldd fails for static executables and scripts: they need nothing.
  while read -r lib; do
    [[ -n "$lib" && -e "$lib" ]] || continue
    [[ -e "$root$lib" ]] && continue
    mkdir -p "$root$(dirname "$lib")"
    cp -L "$lib" "$root$lib"
  done < <(ldd "$exe" 2>/dev/null | awk '/=> \//{print $3} /^[[:space:]]*\/[^ ]+ \(/{print $1}')
  local missing
  missing=$(ldd "$exe" 2>/dev/null | grep 'not found' || true)
  if [[ -n "$missing" ]]; then
    err "$exe needs libraries ldd cannot find:"
    printf '%s\n' "$missing" >&2
    return 1
  fi
}

# Puts the kernel module $2 (path without .ko under kernel/) into the staging root $1,
# decompressing .ko.xz / .ko.zst / .ko.gz.
stage_module() {
  local root=$1 rel=$2
  local src=$kernel_root/lib/modules/$kernel_version/kernel/$rel
  local dst
  dst=$root/lib/modules/$kernel_version/$(basename "$rel").ko
  mkdir -p "$(dirname "$dst")"
  if [[ -f "$src.ko" ]]; then cp "$src.ko" "$dst"
  elif [[ -f "$src.ko.xz" ]]; then xz -dc "$src.ko.xz" >"$dst"
  elif [[ -f "$src.ko.zst" ]]; then zstd -qdc "$src.ko.zst" >"$dst"
  elif [[ -f "$src.ko.gz" ]]; then gzip -dc "$src.ko.gz" >"$dst"
  else
    err "kernel module $rel.ko(.xz|.zst|.gz) not found under $kernel_root/lib/modules/$kernel_version"
    return 1
  fi
}

# Writes the directory $1 as a gzip'd newc cpio archive $2, every file owned by root.
write_cpio() {
  (cd "$1" && find . -mindepth 1 | LC_ALL=C sort | cpio --quiet -o -H newc -R 0:0 | gzip -4) >"$2"
}

# Builds (once, cached) the part of the initramfs that does not depend on the test: busybox,
# modules, can-utils, ip, /init. Sets base_cpio.
build_base() {
  local busybox ipbin
  busybox=$(command -v busybox) || cannot_run "busybox is not installed (busybox-static)"
  ipbin=$(PATH="/usr/sbin:/sbin:$PATH" command -v ip) || cannot_run "iproute2's ip is not installed"
  local tools=() t
  for t in "${kCanUtils[@]}"; do
    if command -v "$t" >/dev/null 2>&1; then tools+=("$(command -v "$t")"); fi
  done
  ((${#tools[@]})) || cannot_run "can-utils is not installed"
  local host_tools=()
  for t in "${kHostTools[@]}"; do
    t=$(command -v "$t") || cannot_run "$t is not installed"
    host_tools+=("$t")
  done
  # The cache key covers everything the base is made of.
  local key
  key=$( {
    echo "$kHarnessVersion $kernel_version"
    guest_init
    printf '%s\n' "${kModules[@]}"
    ls -lL "$busybox" "$ipbin" "${tools[@]}" "${host_tools[@]}" \
      "$kernel_root/boot/vmlinuz-$kernel_version"
  } | sha256sum | cut -c1-16)
  base_cpio=$cache_dir/base-$key.cpio.gz
  [[ -s "$base_cpio" ]] && return 0
  mkdir -p "$cache_dir"
  (
    flock 9
    [[ -s "$base_cpio" ]] && exit 0
    local stage
    stage=$(mktemp -d "$cache_dir/base-stage.XXXXXX")
    trap 'rm -rf "$stage"' EXIT
    mkdir -p "$stage"/{bin,sbin,usr/bin,usr/sbin,usr/local/bin,etc,proc,sys,dev,tmp,run,root,opt/bin,opt/data,var}
    ln -s ../run "$stage/var/run"
    cp -L "$busybox" "$stage/bin/busybox"
    stage_libraries "$stage" "$busybox"
    cp -L "$ipbin" "$stage/usr/sbin/ip"
    stage_libraries "$stage" "$ipbin"
    for t in "${tools[@]}" "${host_tools[@]}"; do
      cp -L "$t" "$stage/usr/bin/"
      stage_libraries "$stage" "$t"
    done
    ln -s /usr/bin/dash "$stage/bin/sh"
    # busybox applets for everything not provided by a real binary above (ip stays iproute2's).
    local applet
    while read -r applet; do
      [[ "$applet" == */busybox || -e "$stage/$applet" ]] && continue
      [[ -e "$stage/usr/sbin/$(basename "$applet")" || -e "$stage/usr/bin/$(basename "$applet")" ]] &&
        continue
      mkdir -p "$stage/$(dirname "$applet")"
      ln -s /bin/busybox "$stage/$applet"
    done < <("$busybox" --list-full)
    local m
    for m in "${kModules[@]}"; do stage_module "$stage" "$m"; done
    [[ -d /etc/iproute2 ]] && cp -rL /etc/iproute2 "$stage/etc/"
    printf 'root:x:0:0:root:/root:/bin/sh\nnobody:x:65534:65534:nobody:/nonexistent:/bin/false\n' \
      >"$stage/etc/passwd"
    printf 'root:x:0:\nnogroup:x:65534:\n' >"$stage/etc/group"
    printf '127.0.0.1 localhost\n::1 localhost\n' >"$stage/etc/hosts"
    local names=""
    for m in "${kModules[@]}"; do names+="$(basename "$m") "; done
    guest_init | sed "s|__MODULES__|${names% }|" >"$stage/init"
    chmod 755 "$stage/init"
    write_cpio "$stage" "$base_cpio.tmp.$$"
    mv "$base_cpio.tmp.$$" "$base_cpio"
    # Bases made by older harnesses or from older packages are of no further use.
    find "$cache_dir" -maxdepth 1 -name 'base-*.cpio.gz' ! -path "$base_cpio" -delete
  ) 9>"$cache_dir/.lock" || { err "building the guest's base initramfs failed"; exit 1; }
}

# Builds the per-run part of the initramfs in $run_dir; sets run_cpio.
build_run_part() {
  local stage=$run_dir/stage
  mkdir -p "$stage/opt/bin" "$stage/opt/data"
  local b f
  for b in "${bins[@]}"; do
    cp -L "$b" "$stage/opt/bin/"
    stage_libraries "$stage" "$b" || exit 1
  done
  for f in "${files[@]}"; do cp -rL "$f" "$stage/opt/data/"; done
  cp "$scenario" "$stage/opt/scenario.sh"
  {
    echo "TEST_NAME='${name//\'/}'"
    echo "SHELL_MODE=$shell"
    echo "COLLECT_OUT=$([[ -n "$out_dir" ]] && echo 1 || echo 0)"
  } >"$stage/opt/run.conf"
  run_cpio=$run_dir/run.cpio.gz
  write_cpio "$stage" "$run_cpio"
  rm -rf "$stage"
}

run_guest() {
  command -v qemu-system-x86_64 >/dev/null 2>&1 ||
    cannot_run "qemu-system-x86_64 is not installed (qemu-system-x86) and the host has no vcan"
  find_kernel
  mkdir -p "$cache_dir/runs"
  build_base
  prepare_kernel_image
  run_dir=$(mktemp -d "$cache_dir/runs/${name//[^A-Za-z0-9_.-]/_}.XXXXXX")
  build_run_part
  local initrd=$run_dir/initrd.cpio.gz
  # The kernel unpacks concatenated archives in order; the run part overrides the base.
  cat "$base_cpio" "$run_cpio" >"$initrd"
  rm -f "$run_cpio"

  local smp=${PUMPTHERM_VCAN_SMP:-1}
  if [[ ! "$smp" =~ ^[1-8]$ ]]; then
    err "PUMPTHERM_VCAN_SMP: '$smp' is not a CPU count from 1 to 8"; exit 2
  fi
  local qemu=(qemu-system-x86_64 -m 512 -smp "$smp" -no-reboot -nodefaults -no-user-config -display none
    -kernel "$guest_kernel_image" -initrd "$initrd"
    -append "console=ttyS0 quiet panic=-1")
  if ((shell)); then
    say "mode=guest kernel=${kernel_version} test=${name} (interactive shell; Ctrl-a x kills QEMU)"
    local rc=0
    "${qemu[@]}" -serial mon:stdio || rc=$?
    say "run directory: $run_dir"
    exit "$rc"
  fi

  local console=$run_dir/console.log result=$run_dir/result.log
  : >"$console"
  : >"$result"
  local start
  start=$(now_s)
  # QEMU dies with the harness, even when the harness is killed outright (CTest's timeout).
  local reaper=()
  if command -v setpriv >/dev/null 2>&1; then reaper=(setpriv --pdeathsig KILL); fi
  "${reaper[@]}" "${qemu[@]}" -serial "file:$console" -serial "file:$result" </dev/null \
    >"$run_dir/qemu.log" 2>&1 &
  local qemu_pid=$!
  # shellcheck disable=SC2064
  trap "kill $qemu_pid 2>/dev/null || true" EXIT INT TERM

  # The guest's BEGIN marker carries "kernel=VERSION".
  guest_on_begin() { say "mode=guest kernel=${1#kernel=} test=${name} (QEMU TCG, ${smp} CPU)"; }
  guest_watch "$qemu_pid" "$start" "$console" "$result"
  trap - EXIT INT TERM
  guest_verdict "$console"
}

# ---------------------------------------------------------------------------------------------

kind=""
if [[ "$mode" != "guest" ]]; then kind=$(native_kind); fi
if [[ -n "$kind" ]]; then run_native "$kind"; fi
if [[ "$mode" == "native" ]]; then cannot_run "--mode native, but the host has no usable vcan"; fi
if [[ "$mode" == "host" ]]; then cannot_run "--mode host, but the host has no vcan0"; fi
run_guest
