#!/usr/bin/env bash
# The demo live on vcan0 (tools/demo.sh --live calls this after simulating): canplayer replays
# the recording onto vcan0 in real time (20 minutes), pumpthermd listens on vcan0 with LCM on,
# and `pumptherm-spy` (in another terminal) shows its messages. Needs a kernel with vcan
# (`sudo modprobe vcan`); this script creates vcan0 if it can.
#   tools/demo-live.sh [DEMO_DIR]     (default demo-out, as written by tools/demo.sh)
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-demo-out}
build=${PUMPTHERM_BUILD_DIR:-build}
[[ -f "$out/demo.log" ]] || { echo "demo-live: $out/demo.log is missing; run tools/demo.sh first" >&2; exit 2; }
if ! ip link show vcan0 >/dev/null 2>&1; then
  if ! { modprobe vcan 2>/dev/null || sudo modprobe vcan; } ||
     ! { ip link add dev vcan0 type vcan 2>/dev/null || sudo ip link add dev vcan0 type vcan; }; then
    echo "demo-live: no vcan0 and cannot create it (this kernel has no vcan?); tools/demo.sh runs offline" >&2
    exit 1
  fi
fi
ip link set up vcan0 2>/dev/null || sudo ip link set up vcan0
config=$(mktemp --suffix=.toml)
trap 'rm -f "$config"; kill "${daemon:-0}" 2>/dev/null || true' EXIT
sed -e 's/^interface = "can0"/interface = "vcan0"/' -e "s#^\[\[can\]\]#[[can]]#" tools/demo/pumpthermd-demo.toml >"$config"
echo "demo-live: pumpthermd on vcan0, LCM on udpm://239.255.76.67:7667?ttl=0"
echo "demo-live: watch with:  tools/pumptherm-spy    or:  candump -L vcan0,200:700"
"$build"/daemon/pumpthermd --config "$config" &
daemon=$!
sleep 1
echo "demo-live: replaying $out/demo.log onto vcan0 in real time (20 minutes; Ctrl-C stops)"
canplayer -I "$out/demo.log" vcan0=can0
kill -TERM "$daemon"
wait "$daemon" || true
