#!/usr/bin/env bash
# The demo live on vcan0 (tools/demo.sh --live calls this after simulating): canplayer replays
# the recording onto vcan0 in real time (20 minutes), pumpthermd listens on vcan0 with LCM on and
# shows its pump table every 5 s, candump records what the gateway sends, and `pumptherm watch`
# or `pumptherm-spy` (in another terminal) show its LCM messages. Needs a kernel with vcan (`sudo modprobe vcan`);
# this script creates vcan0 if it can. The vcan test vcan.daemon_live_demo runs it in the guest.
#   tools/demo-live.sh [DEMO_DIR]     (default demo-out, as written by tools/demo.sh)
# Writes DEMO_DIR/gateway-live.log (the gateway's frames, candump format) and
# DEMO_DIR/pumpthermd-live.txt (its final status line and per-ID counts).
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-demo-out}
build=${PUMPTHERM_BUILD_DIR:-build}
[[ -f "$out/demo.log" ]] || { echo "demo-live: $out/demo.log is missing; run tools/demo.sh first" >&2; exit 2; }
[[ -x "$build/daemon/pumpthermd" ]] || { echo "demo-live: $build/daemon/pumpthermd is missing; run tools/demo.sh first" >&2; exit 2; }
as_root() { if [[ $(id -u) -eq 0 ]]; then "$@"; else sudo "$@"; fi; }
if ! ip link show vcan0 >/dev/null 2>&1; then
  if ! { as_root modprobe vcan 2>/dev/null; as_root ip link add dev vcan0 type vcan; }; then
    echo "demo-live: no vcan0 and cannot create it (this kernel has no vcan?); tools/demo.sh runs offline" >&2
    exit 1
  fi
fi
as_root ip link set up vcan0
work=$(mktemp -d)
config=$work/pumpthermd.toml
daemon=0
capture=0
stop() {
  if [[ $daemon != 0 ]]; then kill -TERM "$daemon" 2>/dev/null || true; wait "$daemon" 2>/dev/null || true; fi
  if [[ $capture != 0 ]]; then kill "$capture" 2>/dev/null || true; wait "$capture" 2>/dev/null || true; fi
  rm -rf "$work"
}
trap stop EXIT
sed -e 's/^interface = "can0"/interface = "vcan0"/' tools/demo/pumpthermd-demo.toml >"$config"
frames=$(wc -l <"$out/demo.log")
echo "demo-live: pumpthermd on vcan0, LCM on udpm://239.255.76.67:7667?ttl=0"
echo "demo-live: watch in another terminal with:  $build/tools/pumptherm watch --url 'udpm://239.255.76.67:7667?ttl=0'"
echo "demo-live:   or the LCM viewer:  $build/tools/pumptherm-spy --url='udpm://239.255.76.67:7667?ttl=0'"
echo "demo-live:   or the CAN frames:  candump -L vcan0,200:700"
candump -L vcan0,200:700,400:700,600:700 >"$out/gateway-live.log" &
capture=$!
"$build"/daemon/pumpthermd --config "$config" --table --table-period 5 >"$out/pumpthermd-live.txt" &
daemon=$!
sleep 1  # its sockets are bound well within this (it logs "listening on vcan0")
kill -0 "$daemon" 2>/dev/null || { daemon=0; echo "demo-live: pumpthermd exited at start" >&2; exit 1; }
echo "demo-live: replaying $out/demo.log ($frames frames) onto vcan0 in real time (Ctrl-C stops)"
canplayer -I "$out/demo.log" vcan0=can0
sleep 1.5
kill -TERM "$daemon"
wait "$daemon" || { echo "demo-live: pumpthermd failed" >&2; daemon=0; exit 1; }
daemon=0
sleep 0.3
kill "$capture" 2>/dev/null || true
wait "$capture" 2>/dev/null || true
capture=0
echo
echo "demo-live: done. The gateway's frames are in $out/gateway-live.log ($(wc -l <"$out/gateway-live.log") frames);"
echo "demo-live: its final status: $(head -n 1 "$out/pumpthermd-live.txt")"
