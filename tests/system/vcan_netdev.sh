#!/bin/sh
# System test: the example vcan setup for test benches, systemd/vcan0.netdev
# and vcan0.network, makes vcan0 with systemd-networkd and brings it up; a frame sent on it is
# received. Runs as root in the guest (tests/system/run_system_test.sh), started without vcan0.
set -eu
T=vcan_netdev
fail() {
  echo "$T: FAIL: $*"
  networkctl status vcan0 --no-pager 2>&1 | sed 's/^/  /' || true
  journalctl -u systemd-networkd --no-pager 2>&1 | tail -n 20 | sed 's/^/  /' || true
  exit 1
}
if ip link show vcan0 >/dev/null 2>&1; then fail "vcan0 exists before the test"; fi
mkdir -p /etc/systemd/network
cp "$DATA_DIR/vcan0.netdev" "$DATA_DIR/vcan0.network" /etc/systemd/network/
systemctl enable --now systemd-networkd >/dev/null 2>&1 || fail "systemd-networkd does not start"
n=0
until ip link show vcan0 2>/dev/null | grep -q "state UNKNOWN\|state UP"; do
  n=$((n + 1)); [ "$n" -le 100 ] || fail "vcan0 not up 20 s after networkd started"; sleep 0.2
done
ip -details link show vcan0 | sed 's/^/  /'
ip -details link show vcan0 | grep -q "vcan" || fail "vcan0 is not of kind vcan"
if command -v candump >/dev/null 2>&1 && command -v cansend >/dev/null 2>&1; then
  candump -n 1 -T 5000 vcan0 > /tmp/rx.txt &
  sleep 0.5
  cansend vcan0 123#DEADBEEF
  wait || true
  grep -q "123 *\[4\] *DE AD BE EF" /tmp/rx.txt || { cat /tmp/rx.txt; fail "frame not received on vcan0"; }
  echo "$T: frame 123#DEADBEEF received on vcan0"
else
  echo "$T: note: can-utils not in the guest; the link was checked only"
fi
echo "$T: PASS"
