#!/usr/bin/env bash
# Runs one system test scenario: a POSIX sh script run as root inside a Debian 12 guest booted
# with systemd (QEMU, TCG), after the binaries under test and the systemd units have been
# installed in it, vcan0 created and the loopback given a multicast route.
#
# How (docs/testing-system.md):
# - A base disk image is built once and cached: debootstrap (minbase) of Debian bookworm with
#   systemd, udev, kmod, iproute2, procps, can-utils and the run-time libraries of our binaries,
#   the guest kernel's modules (unpacked by tools/setup.sh), and a oneshot unit that runs the
#   test's runner from the test's disk after boot; then `mke2fs -t ext4 -d` (no loop mount). A
#   small busybox initramfs loads virtio/ext4 from the same modules and switch_roots to /dev/vda.
#   Building it needs root and the Debian mirror. Three cached layers (debootstrap tarball, disk
#   image, initramfs), each keyed by a hash of what it is made of.
# - Each run boots the base with QEMU's snapshot=on (writes go to a temporary qcow2 overlay in
#   $TMPDIR or /var/tmp that QEMU deletes; the base is never written) plus a second small
#   ext4 disk (mke2fs -d) holding the scenario, binaries, units, data and any shared library the
#   base lacks. The guest's runner installs them, runs the scenario and reports over the second
#   serial port with marker lines; the first serial port is the console (shown when a run fails).
#
# Exit status: the scenario's own status; 1 when the harness fails (guest never reports, setup in
# the guest fails, timeout); 2 for bad arguments; 77 when the test cannot run here (no QEMU, no
# kernel, no base image and not root, debootstrap failing) and CI is not "true". With CI=true such
# a run fails instead.
set -euo pipefail

readonly kHarnessVersion=1
readonly kMarker="@@PUMPTHERM-SYSTEM"
# The host side of the guest protocol (markers, streaming, verdict), shared with the other harness.
# shellcheck source-path=SCRIPTDIR source=../guest/guest_run.sh
source "$(dirname "${BASH_SOURCE[0]}")/../guest/guest_run.sh"
readonly kSuite=bookworm
# The guest's packages. The libraries are those of pumpthermd, pumptherm and the LCM tools (found
# with ldd + dpkg -S on the host), so that the binaries under test, and later the project's .deb,
# install without a network: the guest has none.
# libnss-systemd resolves DynamicUser= names (ps, ls -l, getent).
readonly kPackages=(systemd systemd-sysv libnss-systemd udev kmod iproute2 procps can-utils
  libc6 libstdc++6 libgcc-s1 libsystemd0 libfmt9 libtomlplusplus3 libmuparser2v5 libgomp1
  liblcm1 liblcm-bin libglib2.0-0 libsodium23 libmosquitto1 libssl3 libprotobuf32 zlib1g
  libgoogle-glog0v6 libcholmod3 libcxsparse3 libspqr2 liblapack3 libatlas3-base)
# Loaded by the initramfs, with their dependencies from modules.dep; crc32c is ext4's checksum
# (a soft dependency, which modules.dep does not list).
readonly kBootModules=(virtio_pci virtio_blk crc32c_generic ext4)
readonly kGuestMemory_MiB=1024
# mitigations=off: the page-table isolation and speculation barriers the emulated CPU would get
# only slow TCG down, in a throw-away guest that runs nothing but the test.
readonly kKernelCmdline="console=ttyS0 quiet panic=-1 systemd.show_status=1 net.ifnames=0 mitigations=off"

usage() {
  cat <<'EOF'
usage: run_system_test.sh [options] SCENARIO
       run_system_test.sh [options] --build-base

Runs SCENARIO (a POSIX sh script, run as root) in a Debian 12 guest with systemd, after
installing the binaries and units under test.

options:
  --bin PATH        a binary under test (repeatable). Installed at the path an installed unit's
                    ExecStart= names for a program of the same name (e.g. /usr/sbin/pumpthermd),
                    otherwise in /usr/local/bin. Shared libraries the guest lacks go with it.
  --unit PATH       a systemd unit, installed in /etc/systemd/system (repeatable)
  --file PATH       a data file or directory, in $DATA_DIR (read-only) (repeatable)
  --timeout S       give up after S seconds of guest run (default $PUMPTHERM_SYSTEM_TIMEOUT or
                    600); building the base image is not counted
  --cache-dir DIR   where the base image is cached (default $PUMPTHERM_SYSTEM_CACHE, else
                    $PUMPTHERM_CACHE/system = /var/cache/pumptherm/system when it is writable or
                    already holds the base, else ~/.cache/pumptherm-system)
  --out-dir DIR     copy the files the scenario wrote under $OUT_DIR back to DIR
  --name NAME       test name used in messages (default: the scenario's file name)
  --no-vcan         do not create vcan0 before the scenario
  --build-base      only build (or find) the cached base image, then exit
  --verbose         also stream the guest's console (kernel and systemd messages)
  --keep            keep the run directory (disks, console log) even on success
  --shell           interactive: the console is this terminal; after the scenario, a root shell
                    in the guest (leave with `poweroff`; Ctrl-a x kills QEMU)
  -h, --help        this text

environment:
  PUMPTHERM_CACHE          where tools/setup.sh unpacked the guest kernel (/var/cache/pumptherm)
  PUMPTHERM_DEBIAN_MIRROR  Debian mirror for debootstrap (default http://deb.debian.org/debian)
  CI=true                  a test that cannot run here fails instead of skipping (exit 77)

example:
  tests/system/run_system_test.sh --bin build/daemon/pumpthermd \
      --unit systemd/pumpthermd.service tests/system/unit_ready.sh
EOF
}

say() { printf 'system: %s\n' "$*"; }
err() { printf 'system: error: %s\n' "$*" >&2; }

cannot_run() {
  if [[ "${CI:-}" == "true" ]]; then
    err "cannot run ${name:-system test}: $* (CI=true: system tests must run, not skip)"
    exit 1
  fi
  say "SKIP ${name:-system test}: $*"
  exit 77
}

bins=()
units=()
files=()
timeout_s=${PUMPTHERM_SYSTEM_TIMEOUT:-600}
cache_dir=${PUMPTHERM_SYSTEM_CACHE:-}
out_dir=""
name=""
vcan=1
base_only=0
verbose=0
keep=0
shell=0
scenario=""

while (($#)); do
  case "$1" in
    --bin) bins+=("${2:?--bin needs a path}"); shift 2 ;;
    --unit) units+=("${2:?--unit needs a path}"); shift 2 ;;
    --file) files+=("${2:?--file needs a path}"); shift 2 ;;
    --timeout) timeout_s=${2:?--timeout needs seconds}; shift 2 ;;
    --cache-dir) cache_dir=${2:?--cache-dir needs a directory}; shift 2 ;;
    --out-dir) out_dir=${2:?--out-dir needs a directory}; shift 2 ;;
    --name) name=${2:?--name needs a name}; shift 2 ;;
    --no-vcan) vcan=0; shift ;;
    --build-base) base_only=1; shift ;;
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
if ((base_only)); then
  [[ -z "$scenario" ]] || { err "--build-base takes no SCENARIO"; exit 2; }
  name=${name:-base}
else
  if [[ -z "$scenario" ]]; then err "no SCENARIO given (see --help)"; exit 2; fi
  [[ -n "$name" ]] || name=$(basename "$scenario" .sh)
  if [[ ! -r "$scenario" ]]; then err "scenario '$scenario' is not a readable file"; exit 2; fi
fi
if [[ ! "$timeout_s" =~ ^[1-9][0-9]*$ ]]; then
  err "--timeout: '$timeout_s' is not a positive whole number of seconds"; exit 2
fi
for b in "${bins[@]}"; do
  if [[ ! -f "$b" || ! -x "$b" ]]; then err "--bin '$b' is not an executable file"; exit 2; fi
done
for u in "${units[@]}"; do
  if [[ ! -f "$u" || ! -r "$u" ]]; then err "--unit '$u' is not a readable file"; exit 2; fi
  case "$u" in
    *.service | *.socket | *.timer | *.target | *.path | *.netdev | *.network | *.link) ;;
    *) err "--unit '$u': not a systemd unit file name (.service, .socket, .timer, ...)"; exit 2 ;;
  esac
done
for f in "${files[@]}"; do
  if [[ ! -r "$f" ]]; then err "--file '$f' is not readable"; exit 2; fi
done

[[ -z "$scenario" ]] || scenario=$(abspath "$scenario")
for i in "${!bins[@]}"; do bins[i]=$(abspath "${bins[i]}"); done
for i in "${!units[@]}"; do units[i]=$(abspath "${units[i]}"); done
for i in "${!files[@]}"; do files[i]=$(abspath "${files[i]}"); done
[[ -z "$out_dir" ]] || { mkdir -p "$out_dir" && out_dir=$(cd "$out_dir" && pwd -P); }


# ---------------------------------------------------------------------------------------------
# What goes into the guest
# ---------------------------------------------------------------------------------------------

# /init of the boot initramfs (busybox sh): loads the modules listed in /modules/order, mounts
# /dev/vda and hands over to systemd.
guest_init() {
  cat <<'EOF'
#!/bin/busybox sh
# PID 1 of the boot initramfs of the system test guest (written by run_system_test.sh).
/bin/busybox --install -s /bin
export PATH=/bin
mount -t proc proc /proc
mount -t sysfs sysfs /sys
mount -t devtmpfs devtmpfs /dev
fail() {
  echo "pumptherm-system-initramfs: $*"
  echo "@@PUMPTHERM-SYSTEM-SETUP-FAILED initramfs: $*@@" >/dev/ttyS1
  sleep 1
  poweroff -f
}
while read -r m; do
  insmod "/modules/$m" || fail "insmod $m"
done </modules/order
tries=0
until [ -b /dev/vda ]; do
  tries=$((tries + 1))
  [ "$tries" -le 100 ] || fail "no /dev/vda after 10 s (the root disk)"
  sleep 0.1
done
mkdir -p /newroot
mount -t ext4 -o rw,noatime /dev/vda /newroot || fail "mount -t ext4 /dev/vda"
# /sbin/init is an absolute symlink into the new root: test the link, not its target here.
[ -L /newroot/sbin/init ] || [ -e /newroot/sbin/init ] || fail "/dev/vda has no /sbin/init"
umount /proc /sys /dev
exec switch_root /newroot /sbin/init
EOF
}

# The base image's part of the runner, run by pumptherm-system-test.service once the boot has
# reached multi-user.target: mounts the test's disk (/dev/vdb) and runs the runner it holds, so
# that changing the runner does not need a new base image.
guest_boot_hook() {
  cat <<'EOF'
#!/bin/sh
# Mounts the system test's disk and runs its runner (written by run_system_test.sh).
mnt=/opt/pumptherm-test
mkdir -p "$mnt"
if ! mount -o ro /dev/vdb "$mnt" || [ ! -r "$mnt/runner.sh" ]; then
  echo "pumptherm-system: cannot mount /dev/vdb (the test's disk) or it has no runner.sh"
  echo "@@PUMPTHERM-SYSTEM-SETUP-FAILED mount /dev/vdb (the test's disk)@@" >/dev/ttyS1
  systemctl poweroff --force
  exit 1
fi
exec /bin/sh "$mnt/runner.sh" "$mnt"
EOF
}

# The runner in the guest (on the test's disk): installs what the disk holds, runs the scenario,
# reports on /dev/ttyS1 and powers off.
guest_runner() {
  cat <<'EOF'
#!/bin/sh
# Runs the system test that this disk holds (written by tests/system/run_system_test.sh).
export PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin HOME=/root LANG=C.UTF-8
mnt=$1
out=/dev/ttyS1
stty -F "$out" raw -echo 2>/dev/null
say() { echo "pumptherm-system-runner: $*"; }
setup_failed() {
  say "setup failed: $*"
  echo "@@PUMPTHERM-SYSTEM-SETUP-FAILED $*@@" >"$out"
  systemctl poweroff --force
  exit 1
}
. "$mnt/run.conf"
[ "$SHELL_MODE" = 1 ] && out=/dev/console
# Shared libraries the base image lacks, at their host paths (through the merged-/usr links:
# /lib is a symbolic link to usr/lib and stays one).
if [ -d "$mnt/libs" ]; then
  tar -C "$mnt/libs" -cf - . | tar -C / --keep-directory-symlink -xf - || setup_failed "copying libraries"
  ldconfig
fi
while read -r bin dest; do
  install -D -m 0755 "$mnt/bin/$bin" "$dest" || setup_failed "installing $bin as $dest"
  if ldd "$dest" 2>/dev/null | grep -q 'not found'; then
    setup_failed "$dest needs libraries the guest lacks: $(ldd "$dest" | grep 'not found' | tr -s ' \t\n' ' ')"
  fi
done <"$mnt/bin.map"
units_installed=0
for u in "$mnt"/units/*; do
  [ -e "$u" ] || continue
  install -m 0644 "$u" /etc/systemd/system/ || setup_failed "installing unit $u"
  units_installed=1
done
# Only new units need a reload (about 4 s under TCG).
if [ "$units_installed" = 1 ]; then
  systemctl daemon-reload || setup_failed "systemctl daemon-reload"
fi
if [ "$VCAN" = 1 ]; then
  modprobe vcan || setup_failed "modprobe vcan"
  ip link add dev vcan0 type vcan || setup_failed "ip link add dev vcan0 type vcan"
  ip link set vcan0 up || setup_failed "ip link set vcan0 up"
fi
ip link set lo up && ip link set lo multicast on && ip route add 224.0.0.0/4 dev lo ||
  setup_failed "loopback with a multicast route"
export DATA_DIR="$mnt/data" WORK_DIR=/root/work OUT_DIR=/root/out SYSTEM_TEST_NAME="$TEST_NAME"
mkdir -p "$WORK_DIR" "$OUT_DIR"
read -r up_s _ </proc/uptime
echo "@@PUMPTHERM-SYSTEM-BEGIN kernel=$(uname -r) systemd=$(systemctl --version | awk 'NR == 1 { print $2 }') uptime_s=$up_s@@" >"$out"
(cd "$WORK_DIR" && exec sh "$mnt/scenario.sh") </dev/null >"$out" 2>&1
rc=$?
say "the scenario exited with code $rc"
if [ "$COLLECT_OUT" = 1 ]; then
  {
    echo "@@PUMPTHERM-SYSTEM-OUT-BEGIN@@"
    tar -C "$OUT_DIR" -cf - . | gzip -1 | base64
    echo "@@PUMPTHERM-SYSTEM-OUT-END@@"
  } >"$out"
fi
echo "@@PUMPTHERM-SYSTEM-EXIT $rc@@" >"$out"
if [ "$SHELL_MODE" = 1 ]; then
  mkdir -p /run/systemd/system/serial-getty@ttyS0.service.d
  printf '[Service]\nExecStart=\nExecStart=-/sbin/agetty --autologin root --keep-baud 115200,57600,38400,9600 %%I $TERM\n' \
    >/run/systemd/system/serial-getty@ttyS0.service.d/autologin.conf
  systemctl daemon-reload
  systemctl restart serial-getty@ttyS0.service
  say "scenario exit code $rc; root shell on this console (test files in $mnt, work in $WORK_DIR); leave with: poweroff"
  exit 0
fi
systemctl poweroff --force
EOF
}

guest_runner_unit() {
  cat <<'EOF'
[Unit]
Description=pumptherm system test runner (tests/system/run_system_test.sh)
After=multi-user.target

[Service]
Type=oneshot
ExecStart=/usr/local/libexec/pumptherm-system-boot
StandardOutput=journal+console
StandardError=journal+console
TimeoutStartSec=infinity

[Install]
WantedBy=multi-user.target
EOF
}

# Makes the debootstrapped tree $1 a bootable test guest (no chroot: plain files).
configure_root() {
  local r=$1
  echo pumptherm-guest >"$r/etc/hostname"
  printf '127.0.0.1 localhost\n127.0.1.1 pumptherm-guest\n::1 localhost\n' >"$r/etc/hosts"
  # The initramfs mounts the root read-write; no fsck of a disk that is a throw-away overlay.
  echo '/dev/vda / ext4 rw,noatime 0 0' >"$r/etc/fstab"
  # Root logs in on the console without a password (--shell); the guest has no network.
  sed -i 's/^root:[^:]*:/root::/' "$r/etc/shadow"
  # Timers and jobs that only cost boot time in a guest that lives for a minute.
  local u
  # Under TCG every process started at boot costs a fraction of a second.
  for u in apt-daily.timer apt-daily-upgrade.timer dpkg-db-backup.timer e2scrub_all.timer \
    e2scrub_reap.service fstrim.timer systemd-tmpfiles-clean.timer \
    modprobe@dm_mod.service modprobe@efi_pstore.service modprobe@fuse.service \
    modprobe@loop.service dev-hugepages.mount sys-kernel-debug.mount sys-kernel-tracing.mount \
    sys-fs-fuse-connections.mount getty-static.service getty@tty1.service; do
    ln -sf /dev/null "$r/etc/systemd/system/$u"
  done
  # The journal stays in /run: nothing to flush to the disk at boot.
  mkdir -p "$r/etc/systemd/journald.conf.d"
  printf '[Journal]\nStorage=volatile\n' >"$r/etc/systemd/journald.conf.d/pumptherm-test.conf"
  mkdir -p "$r/etc/systemd/system.conf.d"
  printf '[Manager]\nDefaultTimeoutStopSec=15s\n' >"$r/etc/systemd/system.conf.d/pumptherm-test.conf"
  mkdir -p "$r/usr/local/libexec"
  guest_boot_hook >"$r/usr/local/libexec/pumptherm-system-boot"
  chmod 755 "$r/usr/local/libexec/pumptherm-system-boot"
  guest_runner_unit >"$r/etc/systemd/system/pumptherm-system-test.service"
  mkdir -p "$r/etc/systemd/system/multi-user.target.wants"
  ln -sf ../pumptherm-system-test.service \
    "$r/etc/systemd/system/multi-user.target.wants/pumptherm-system-test.service"
  # apt in the guest works from local .deb files only: no lists, no network.
  rm -rf "$r/var/cache/apt/archives/"*.deb
}

# ---------------------------------------------------------------------------------------------
# Base image
# ---------------------------------------------------------------------------------------------


# Chooses cache_dir when none was given: the shared cache when it is usable.
choose_cache_dir() {
  [[ -n "$cache_dir" ]] && return 0
  local shared=${PUMPTHERM_CACHE:-/var/cache/pumptherm}/system
  if { mkdir -p "$shared" 2>/dev/null && [[ -w "$shared" ]]; } ||
    compgen -G "$shared/system-base-*.img" >/dev/null; then
    cache_dir=$shared
  else
    cache_dir=${XDG_CACHE_HOME:-${HOME:-/tmp}/.cache}/pumptherm-system
  fi
}

# Three cached layers, each keyed by a hash of what it is made of, so that changing one part
# rebuilds only that part: the debootstrap tree (a tar; minutes, needs the mirror), the disk image
# (tree + configure_root + kernel modules; seconds) and the boot initramfs (seconds).
debootstrap_key() {
  {
    echo "debootstrap $kHarnessVersion $kSuite ${PUMPTHERM_DEBIAN_MIRROR:-}"
    printf '%s\n' "${kPackages[@]}"
  } | sha256sum | cut -c1-16
}

image_key() {
  {
    echo "image $1 $kernel_version"
    declare -f configure_root build_image
    guest_boot_hook
    guest_runner_unit
    ls -lL "$kernel_root/boot/vmlinuz-$kernel_version"
  } | sha256sum | cut -c1-16
}

initrd_key() {
  {
    echo "initrd $kernel_version"
    printf '%s\n' "${kBootModules[@]}"
    guest_init
    declare -f build_initramfs module_closure
    ls -lL "$kernel_root/boot/vmlinuz-$kernel_version" "$(command -v busybox)"
  } | sha256sum | cut -c1-16
}

# Prints the module files (relative to lib/modules/<ver>) that $2... need, dependencies first,
# from the modules.dep of the module tree $1.
module_closure() {
  local dep_file=$1/modules.dep
  shift
  local -A seen=()
  local -a order=()
  visit() {
    local path=$1 line dep
    [[ -n "${seen[$path]:-}" ]] && return 0
    seen[$path]=1
    line=$(grep -m1 "^${path}:" "$dep_file") || { err "module $path is not in $dep_file"; return 1; }
    for dep in ${line#*:}; do visit "$dep" || return 1; done
    order+=("$path")
  }
  local m path
  for m in "$@"; do
    path=$(grep -m1 -E "(^|/)${m//_/[_-]}\.ko(\.xz|\.zst|\.gz)?:" "$dep_file" | cut -d: -f1)
    [[ -n "$path" ]] || { err "module $m not found in $dep_file"; return 1; }
    visit "$path" || return 1
  done
  printf '%s\n' "${order[@]}"
}

# Builds the boot initramfs $1: busybox, kBootModules with their dependencies (modules.dep made
# by depmod over a tree of symbolic links to the unpacked kernel's modules), guest_init.
build_initramfs() {
  local dst=$1 stage m
  stage=$(mktemp -d)
  mkdir -p "$stage"/{bin,dev,proc,sys,newroot,modules} "$stage/tree/lib/modules"
  cp -L "$(command -v busybox)" "$stage/bin/busybox"
  if ldd "$stage/bin/busybox" >/dev/null 2>&1; then
    err "$(command -v busybox) is not static (install busybox-static)"; rm -rf "$stage"; return 1
  fi
  local modroot=$stage/tree/lib/modules/$kernel_version
  cp -as "$kernel_root/lib/modules/$kernel_version" "$stage/tree/lib/modules/"
  depmod -b "$stage/tree" "$kernel_version" || { err "depmod failed"; rm -rf "$stage"; return 1; }
  local mods
  mods=$(module_closure "$modroot" "${kBootModules[@]}") || { rm -rf "$stage"; return 1; }
  : >"$stage/modules/order"
  while read -r m; do
    local base
    base=$(basename "$m")
    case "$m" in
      *.ko) cp -L "$modroot/$m" "$stage/modules/$base" ;;
      *.ko.xz) xz -dc "$modroot/$m" >"$stage/modules/${base%.xz}"; base=${base%.xz} ;;
      *.ko.zst) zstd -qdc "$modroot/$m" >"$stage/modules/${base%.zst}"; base=${base%.zst} ;;
      *.ko.gz) gzip -dc "$modroot/$m" >"$stage/modules/${base%.gz}"; base=${base%.gz} ;;
    esac
    echo "$base" >>"$stage/modules/order"
  done <<<"$mods"
  rm -rf "$stage/tree"
  guest_init >"$stage/init"
  chmod 755 "$stage/init"
  (cd "$stage" && find . -mindepth 1 | LC_ALL=C sort | cpio --quiet -o -H newc -R 0:0 | gzip -4) >"$dst"
  rm -rf "$stage"
}

# Makes the debootstrap tarball $1 (run under the cache lock). Exits 3 when debootstrap fails.
build_debootstrap_tar() {
  local tar=$1 stage start
  start=$(now_s)
  stage=$(mktemp -d "$cache_dir/system-stage.XXXXXX")
  local mirror=${PUMPTHERM_DEBIAN_MIRROR:-http://deb.debian.org/debian}
  local include
  include=$(IFS=,; echo "${kPackages[*]}")
  say "debootstrap $kSuite from $mirror (once; a few minutes)"
  if ! debootstrap --variant=minbase --include="$include" "$kSuite" "$stage/root" "$mirror" \
    >"$stage/debootstrap.log" 2>&1; then
    err "debootstrap failed; last lines of its log:"
    tail -n 20 "$stage/debootstrap.log" >&2
    [[ -f "$stage/root/debootstrap/debootstrap.log" ]] &&
      tail -n 20 "$stage/root/debootstrap/debootstrap.log" >&2
    rm -rf "$stage"
    exit 3
  fi
  rm -rf "$stage/root/var/cache/apt/archives/"*.deb
  tar --numeric-owner --xattrs -C "$stage/root" -cf "$tar.tmp" . && mv "$tar.tmp" "$tar"
  rm -rf "$stage"
  say "debootstrap took $(elapsed_s "$start") s: $tar"
}

# Makes the disk image $2 and its file list $3 from the debootstrap tarball $1.
build_image() {
  local tar=$1 img=$2 file_list=$3 stage start
  start=$(now_s)
  stage=$(mktemp -d "$cache_dir/system-stage.XXXXXX")
  mkdir "$stage/root"
  tar --numeric-owner --xattrs -C "$stage/root" -xf "$tar" || { rm -rf "$stage"; return 1; }
  configure_root "$stage/root"
  mkdir -p "$stage/root/usr/lib/modules"
  cp -a "$kernel_root/lib/modules/$kernel_version" "$stage/root/usr/lib/modules/"
  depmod -b "$stage/root/usr" "$kernel_version" ||
    { err "depmod of the guest's modules failed"; rm -rf "$stage"; return 1; }
  # Every path in the base, for the per-test check of which libraries the guest lacks.
  (cd "$stage/root" && find . -mindepth 1 -printf '/%P\n' | LC_ALL=C sort) >"$stage/files"
  local used_MiB
  used_MiB=$(du -sm "$stage/root" | cut -f1)
  # Room for what the tests install and write (QEMU's snapshot overlay takes the writes).
  local size_MiB=$((used_MiB + 1536))
  truncate -s "${size_MiB}M" "$stage/base.img"
  if ! mke2fs -q -F -t ext4 -L pumptherm-root -d "$stage/root" "$stage/base.img"; then
    err "mke2fs -d of the base image failed"; rm -rf "$stage"; return 1
  fi
  chmod 0444 "$stage/base.img"
  mv "$stage/files" "$file_list"
  mv "$stage/base.img" "$img"
  rm -rf "$stage"
  say "base image: ${used_MiB} MiB of files in a ${size_MiB} MiB ext4 image, made in $(elapsed_s "$start") s"
}

# Finds or builds the cached base: sets base_img, base_initrd, base_files.
build_base() {
  local dkey ikey rkey
  dkey=$(debootstrap_key)
  ikey=$(image_key "$dkey")
  rkey=$(initrd_key)
  local tar=$cache_dir/system-debootstrap-$dkey.tar
  base_img=$cache_dir/system-base-$ikey.img
  base_files=$cache_dir/system-base-$ikey.files
  base_initrd=$cache_dir/system-initrd-$rkey.cpio.gz
  if [[ -s "$base_img" && -s "$base_files" && -s "$base_initrd" ]]; then
    say "base image $base_img (cached)"
    return 0
  fi
  ((EUID == 0)) || cannot_run "the base image $base_img does not exist and building it needs root (debootstrap): run 'sudo $0 --build-base --cache-dir $cache_dir' once"
  local t
  for t in debootstrap mke2fs cpio gzip depmod tar; do
    PATH="/usr/sbin:/sbin:$PATH" command -v "$t" >/dev/null 2>&1 ||
      cannot_run "$t is not installed (tools/setup.sh installs debootstrap, e2fsprogs, cpio, kmod)"
  done
  mkdir -p "$cache_dir" || cannot_run "cannot create the cache directory $cache_dir"
  local rc=0
  (
    flock 9
    export PATH="/usr/sbin:/sbin:$PATH"
    start=$(now_s)
    [[ -s "$tar" ]] || build_debootstrap_tar "$tar"
    if [[ ! -s "$base_img" || ! -s "$base_files" ]]; then
      build_image "$tar" "$base_img" "$base_files" || exit 1
    fi
    if [[ ! -s "$base_initrd" ]]; then
      build_initramfs "$base_initrd.tmp" && mv "$base_initrd.tmp" "$base_initrd" || exit 1
    fi
    say "base ready in $(elapsed_s "$start") s"
    # Layers made by older harnesses, kernels or package lists are of no further use.
    find "$cache_dir" -maxdepth 1 \( -name 'system-debootstrap-*' -o -name 'system-base-*' \
      -o -name 'system-initrd-*' -o -name 'system-stage.*' \) ! -path "$tar" \
      ! -path "$base_img" ! -path "$base_files" ! -path "$base_initrd" -exec rm -rf {} +
  ) 9>"$cache_dir/.lock" || rc=$?
  if ((rc == 3)); then cannot_run "debootstrap of the base image failed (no mirror reachable?)"; fi
  ((rc == 0)) || { err "building the base image failed"; exit 1; }
}

# ---------------------------------------------------------------------------------------------
# One run
# ---------------------------------------------------------------------------------------------

# True when the base image holds the path $1 (merged /usr: /lib is /usr/lib and so on).
base_has() {
  local p=$1
  case "$p" in
    /lib/* | /lib64/* | /bin/* | /sbin/*) p=/usr$p ;;
  esac
  grep -qxF -e "$1" -e "$p" "$base_files"
}

# Puts into the staging root $1 every shared library of the executable $2 that the base lacks.
stage_missing_libraries() {
  local root=$1 exe=$2 lib real
  if ldd "$exe" 2>/dev/null | grep -q 'not found'; then
    err "$exe needs libraries ldd cannot find here:"
    ldd "$exe" | grep 'not found' >&2
    return 1
  fi
  while read -r lib; do
    [[ -n "$lib" && -e "$lib" ]] || continue
    base_has "$lib" && continue
    real=$(readlink -f "$lib")
    mkdir -p "$root$(dirname "$lib")"
    cp -L "$real" "$root$lib"
    say "the guest lacks $lib: copied from the host"
  done < <(ldd "$exe" 2>/dev/null | awk '/=> \//{print $3} /^[[:space:]]*\/[^ ]+ \(/{print $1}')
}

# Where the binary named $1 goes in the guest: the ExecStart= path of an installed unit that
# names a program of that name, else /usr/local/bin/$1.
guest_path_of() {
  local bin=$1 u path
  for u in "${units[@]}"; do
    while read -r path; do
      path=${path#ExecStart=}
      while [[ "$path" == [-@:+!]* ]]; do path=${path:1}; done   # ExecStart= prefixes
      path=${path%% *}
      if [[ "$path" == /* && "$(basename "$path")" == "$bin" ]]; then
        echo "$path"
        return 0
      fi
    done < <(grep -E '^ExecStart=' "$u")
  done
  echo "/usr/local/bin/$bin"
}

# Builds the test's disk in $run_dir; sets test_img.
build_test_disk() {
  local stage=$run_dir/test
  mkdir -p "$stage/bin" "$stage/units" "$stage/data" "$stage/libs"
  : >"$stage/bin.map"
  local b u f
  for b in "${bins[@]}"; do
    cp -L "$b" "$stage/bin/"
    echo "$(basename "$b") $(guest_path_of "$(basename "$b")")" >>"$stage/bin.map"
    stage_missing_libraries "$stage/libs" "$b" || exit 1
  done
  rmdir "$stage/libs" 2>/dev/null || true
  for u in "${units[@]}"; do cp "$u" "$stage/units/"; done
  for f in "${files[@]}"; do cp -rL "$f" "$stage/data/"; done
  cp "$scenario" "$stage/scenario.sh"
  guest_runner >"$stage/runner.sh"
  {
    echo "TEST_NAME='${name//\'/}'"
    echo "SHELL_MODE=$shell"
    echo "VCAN=$vcan"
    echo "COLLECT_OUT=$([[ -n "$out_dir" ]] && echo 1 || echo 0)"
  } >"$stage/run.conf"
  local used_MiB
  used_MiB=$(du -sm "$stage" | cut -f1)
  test_img=$run_dir/test.img
  truncate -s "$((used_MiB * 2 + 16))M" "$test_img"
  PATH="/usr/sbin:/sbin:$PATH" mke2fs -q -F -t ext4 -L pumptherm-test -d "$stage" "$test_img" ||
    { err "mke2fs -d of the test's disk failed"; exit 1; }
  rm -rf "$stage"
}

run_guest() {
  run_dir=$(mktemp -d "${TMPDIR:-/tmp}/pumptherm-system-${name//[^A-Za-z0-9_.-]/_}.XXXXXX")
  local start
  start=$(now_s)
  build_test_disk
  local qemu=(qemu-system-x86_64 -m "$kGuestMemory_MiB" -smp 1 -no-reboot -nodefaults
    -no-user-config -display none -nic none
    -kernel "$kernel_root/boot/vmlinuz-$kernel_version" -initrd "$base_initrd"
    -append "$kKernelCmdline"
    -drive "file=$base_img,format=raw,if=virtio,snapshot=on"
    -drive "file=$test_img,format=raw,if=virtio,readonly=on")
  if ((shell)); then
    say "test=${name}: interactive; the scenario's output and then a root shell come on this terminal (Ctrl-a x kills QEMU)"
    local rc=0
    "${qemu[@]}" -serial mon:stdio -serial "file:$run_dir/result.log" || rc=$?
    say "run directory: $run_dir"
    exit "$rc"
  fi

  local console=$run_dir/console.log result=$run_dir/result.log
  : >"$console"
  : >"$result"
  say "test=${name}: booting the guest (QEMU TCG; staging took $(elapsed_s "$start") s)"
  "${qemu[@]}" -serial "file:$console" -serial "file:$result" </dev/null >"$run_dir/qemu.log" 2>&1 &
  local qemu_pid=$!
  # shellcheck disable=SC2064
  trap "kill $qemu_pid 2>/dev/null || true" EXIT INT TERM

  guest_on_begin() { say "guest ready after ${guest_begin_s} s: $1"; }
  guest_watch "$qemu_pid" "$start" "$console" "$result"
  trap - EXIT INT TERM
  guest_verdict "$console"
}

# ---------------------------------------------------------------------------------------------

command -v qemu-system-x86_64 >/dev/null 2>&1 || cannot_run "qemu-system-x86_64 is not installed (qemu-system-x86)"
command -v busybox >/dev/null 2>&1 || cannot_run "busybox is not installed (busybox-static)"
find_kernel
choose_cache_dir
build_base
((base_only)) && exit 0
run_guest
