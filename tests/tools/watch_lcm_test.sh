#!/bin/sh
# pumptherm watch over real UDP multicast: pumptherm-lcm-demo publishes two pumps' TEMPS and
# ALARM messages inside a network namespace made here (multicast on its loopback only, ttl=0:
# nothing leaves the namespace), and `pumptherm watch` must show both pumps, and `watch pumpB`
# every node of pumpB.
#
#   watch_lcm_test.sh BUILD_DIR
#
# Needs root (ip netns). Exits 77 (skip) when it cannot make the namespace, 1 on failure.
set -eu
build=$(CDPATH= cd -- "$1" && pwd)
ns="pumptherm-watch-$$"
[ "$(id -u)" -eq 0 ] || { echo "SKIP: needs root for ip netns"; exit 77; }
ip netns add "$ns" 2>/dev/null || { echo "SKIP: ip netns add failed (no network namespaces here)"; exit 77; }
trap 'ip netns del "$ns" 2>/dev/null || true' EXIT
ip -n "$ns" link set lo up
ip -n "$ns" link set lo multicast on
ip -n "$ns" route add 224.0.0.0/4 dev lo
url='udpm://239.255.76.67:7667?ttl=0'
ip netns exec "$ns" "$build/tools/pumptherm-lcm-demo" --url "$url" --duration-s 5 \
  --pumps pumpA pumpB --nodes frame stator winding rotor >/dev/null 2>&1 &
rc=0
out=$(ip netns exec "$ns" "$build/tools/pumptherm" watch --url "$url" --period-s 1.5 --count 2) || rc=$?
detail=$(ip netns exec "$ns" "$build/tools/pumptherm" watch pumpB --url "$url" --period-s 1 --count 1) || rc=$?
wait
echo "$out"
fail=0
[ "$rc" -eq 0 ] || { echo "FAIL: watch exited $rc"; fail=1; }
echo "$detail"
for want in pumpA pumpB "hottest, degC ±2 sd" "diagnosis"; do
  echo "$out" | grep -q -- "$want" || { echo "FAIL: the table lacks '$want'"; fail=1; }
done
for want in "frame " "stator " "winding " "rotor " "estimate, degC (±2 sd): filter" "frame sensor"; do
  echo "$detail" | grep -q -- "$want" || { echo "FAIL: the detail of pumpB lacks '$want'"; fail=1; }
done
[ "$fail" -eq 0 ] && echo "PASS: watch showed both pumps and every node over udpm"
exit "$fail"
