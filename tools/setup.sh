#!/usr/bin/env bash
# Installs every Debian package pumptherm needs, and unpacks a Debian kernel with the CAN modules
# for the vcan test guest. Idempotent and non-interactive; runs as root or through sudo.
#
#   tools/setup.sh            packages + guest kernel
#   tools/setup.sh --no-guest packages only
set -euo pipefail

packages=(
  build-essential cmake ninja-build pkg-config git ca-certificates
  libeigen3-dev libceres-dev libmuparser-dev
  liblcm-dev liblcm-bin liblcm-java libglib2.0-dev
  libsystemd-dev libsodium-dev libtomlplusplus-dev libcli11-dev libfmt-dev
  libgtest-dev libgmock-dev googletest libbenchmark-dev
  clang libclang-rt-14-dev clang-format   # clang-format: tools/format-check.sh (CI's first stage)
  can-utils iproute2 kmod cpio gzip busybox-static qemu-system-x86 debootstrap e2fsprogs
  gnuplot-nox default-jdk-headless libjchart2d-java xvfb xauth xdotool x11-apps imagemagick
  chromium
  lintian dpkg-dev groff-base time
  python3-canmatrix   # the independent DBC decoder of tests/protocol/codec_canmatrix_test.cpp
  libmosquitto-dev protobuf-compiler libprotobuf-dev   # the MQTT Sparkplug B sink (docs/mqtt.md)
  mosquitto python3-paho-mqtt python3-protobuf openssl # its broker test: broker, subscriber, test CA
)

want_guest=1
[[ "${1:-}" == "--no-guest" ]] && want_guest=0

SUDO=""
if [[ $(id -u) -ne 0 ]]; then SUDO="sudo"; fi
export DEBIAN_FRONTEND=noninteractive

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
# Node.js and npm run the independent DBC decoder (candied) in the cross-check test; a machine
# that already has a node with npm (from any source) keeps it.
if ! command -v npm >/dev/null 2>&1; then missing+=(nodejs npm); fi

if ((${#missing[@]})); then
  echo "setup: installing ${missing[*]}"
  $SUDO apt-get update -qq
  $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
else
  echo "setup: all Debian packages present"
fi

if ((want_guest)); then
  # The host kernel has no CAN; the vcan tests boot Debian's kernel in QEMU. We unpack the kernel
  # package instead of installing it, so the host's /boot and initramfs are left alone.
  cache=${PUMPTHERM_CACHE:-/var/cache/pumptherm}
  $SUDO mkdir -p "$cache"
  if [[ ! -f "$cache/kernel/ready" ]]; then
    pkg=$(apt-cache depends linux-image-amd64 2>/dev/null | awk '/Depends: linux-image-[0-9]/{print $2; exit}')
    if [[ -z "$pkg" ]]; then $SUDO apt-get update -qq; pkg=$(apt-cache depends linux-image-amd64 | awk '/Depends: linux-image-[0-9]/{print $2; exit}'); fi
    echo "setup: unpacking $pkg for the vcan guest into $cache/kernel"
    tmp=$(mktemp -d)
    (cd "$tmp" && apt-get download -qq "$pkg" 2>/dev/null || $SUDO apt-get download -qq "$pkg")
    $SUDO rm -rf "$cache/kernel"
    $SUDO mkdir -p "$cache/kernel"
    $SUDO dpkg-deb -x "$tmp"/linux-image-*.deb "$cache/kernel"
    rm -rf "$tmp"
    $SUDO touch "$cache/kernel/ready"
  fi
  echo "setup: guest kernel $(ls "$cache/kernel/boot" | grep vmlinuz)"
fi

# --- candied for the DBC cross-check ---
# tests/protocol/codec_candied_test.cpp decodes frames with npm's candied as an independent
# decoder. `npm ci` installs exactly what tests/protocol/candied/package-lock.json pins; it runs
# as the invoking user (not through sudo) and only when the installed version differs.
candied_dir="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)/tests/protocol/candied"
candied_want=$(sed -n 's/.*"candied": "\([0-9.]*\)".*/\1/p' "$candied_dir/package.json" | head -n 1)
candied_have=$( (sed -n 's/^ *"version": "\([^"]*\)".*/\1/p' "$candied_dir/node_modules/candied/package.json" 2>/dev/null || true) | head -n 1)
if [[ "$candied_have" != "$candied_want" ]]; then
  echo "setup: npm ci in $candied_dir (candied $candied_want)"
  (cd "$candied_dir" && npm ci --no-audit --no-fund --loglevel=error)
else
  echo "setup: candied $candied_have present"
fi
# --- end candied ---
