#!/bin/sh
# System test: docs/operator-guide.md, run as written. Every ```sh block of
# the guide is extracted (in order; ```sh norun blocks are counted and skipped) and run as root
# with `sh -e` in one working directory that holds the built .deb, in a fresh Debian 12 guest
# whose CAN interface is a vcan named can0 (as the guide's bench note says). A block that fails
# fails the test; then the outcomes the guide promises are checked.
# Runs in the guest (tests/system/run_system_test.sh); $DATA_DIR has the .deb and the guide.
set -eu
T=operator_guide
unit=pumpthermd.service
fail() {
  echo "$T: FAIL: $*"
  systemctl status --no-pager --full "$unit" 2>&1 | sed 's/^/  /' || true
  journalctl -u "$unit" --no-pager -o short-monotonic 2>&1 | tail -n 30 | sed 's/^/  /' || true
  exit 1
}
uptime_s() { cut -d' ' -f1 /proc/uptime; }

ip link add dev can0 type vcan && ip link set up can0 || fail "cannot create the vcan interface can0"
cp "$DATA_DIR"/pumptherm_*.deb "$DATA_DIR"/pumptherm-tools_*.deb "$WORK_DIR/"
guide=$DATA_DIR/operator-guide.md
[ -f "$guide" ] || fail "no operator-guide.md in $DATA_DIR"

# Extract: block_N.sh per ```sh block, with the guide's line number.
mkdir -p "$WORK_DIR/blocks"
awk -v dir="$WORK_DIR/blocks" '
  /^```sh norun/ { skip = 1; norun++; next }
  /^```sh$/      { n++; f = sprintf("%s/block_%02d.sh", dir, n); printf "# guide line %d\n", NR + 1 > f; on = 1; next }
  /^```/         { if (on) close(f); on = 0; skip = 0; next }
  on             { print > f }
  END            { printf "%d %d\n", n, norun > (dir "/count") }' "$guide"
read -r blocks norun <"$WORK_DIR/blocks/count"
echo "$T: $blocks sh blocks to run, $norun marked norun"
[ "$blocks" -ge 10 ] || fail "only $blocks sh blocks found in the guide"

cd "$WORK_DIR"
for b in "$WORK_DIR"/blocks/block_*.sh; do
  name=$(basename "$b" .sh)
  echo "== $T: $name ($(head -n 1 "$b" | sed 's/^# //'))"
  sed -n '2,$p' "$b" | sed 's/^/   $ /'
  t0=$(uptime_s)
  if ! sh -e "$b" >"$WORK_DIR/$name.out" 2>&1; then
    sed 's/^/   | /' "$WORK_DIR/$name.out"
    fail "$name ($(head -n 1 "$b" | sed 's/^# //')) failed"
  fi
  sed 's/^/   | /' "$WORK_DIR/$name.out" | tail -n 15
  echo "   ($(awk -v a="$t0" -v b="$(uptime_s)" 'BEGIN { printf "%.1f", b - a }') s)"
done

# What the guide promises.
grep -q 'OK (1 interface, 3 pumps)' "$WORK_DIR"/block_*.out || fail "no --check-config OK line"
[ "$(tail -n +2 estimates/pump1.csv | wc -l)" -gt 100 ] || fail "estimates/pump1.csv has too few rows"
awk -F, 'NR == 1 { for (i = 1; i <= NF; i++) c[$i] = i; next }
         { v = $c["winding_degC"] } END { exit !(v + 0 > 20 && v + 0 < 200) }' estimates/pump1.csv ||
  fail "estimates/pump1.csv: the last winding_degC is not a plausible temperature"
journalctl -u "$unit" --no-pager | grep -q "pump3: trip: " || fail "pump3 never tripped live"
# The alarm lines carry structured journal fields (daemon/log.hpp LogFields): the trip is found
# by its fields alone, and its VALUE_DEGC is a temperature (the sensor's, over 85 degC).
journalctl -u "$unit" --no-pager -o cat PUMP=pump3 LEVEL=trip | grep -q "^pump3: trip: " ||
  fail "journalctl PUMP=pump3 LEVEL=trip finds no trip line"
journalctl -u "$unit" --no-pager -o export PUMP=pump3 LEVEL=trip |
  awk -F= '$1 == "VALUE_DEGC" { v = $2 } END { exit !(v + 0 > 85 && v + 0 < 200) }' ||
  fail "the trip line's VALUE_DEGC is not the sensor's temperature over its trip level"
echo "$T: journalctl PUMP=pump3 LEVEL=trip: $(journalctl -u "$unit" --no-pager -o cat PUMP=pump3 LEVEL=trip | tail -n 1)"
journalctl -u "$unit" --no-pager | grep -q "alarm clear from 'can:can0' accepted (latched trip cleared)" ||
  fail "the PUMP_CLEAR frame did not clear pump3's latched trip"
grep -q 'pump3: PUMP_CLEAR sent on can0' "$WORK_DIR"/block_*.out ||
  fail "pumptherm clear-trip did not send PUMP_CLEAR on can0"
[ -s disc/model.toml ] || fail "the discrepancy workflow wrote no model"
[ -s /var/lib/pumptherm/state.toml ] || fail "no state saved at stop"
echo "$T: PASS ($blocks blocks run, $norun not run)"
