#!/bin/sh
# Harness check (the system test installs the project's .deb with apt): the
# guest has no network, yet `apt-get install ./x.deb` works for a package whose dependencies are
# the run-time libraries of our binaries, because the base image has them installed; a package
# that needs anything else fails with apt's message rather than hanging on a download.
# Runs as root in the guest (tests/system/run_system_test.sh), without vcan0.
set -eu
T=apt_offline
fail() { echo "$T: FAIL: $*"; exit 1; }

links=$(ip -o link show | awk -F': ' '{ print $2 }' | tr '\n' ' ')
echo "$T: network interfaces: $links"
[ "$links" = "lo " ] || fail "the guest has interfaces besides lo: $links (it must have no network)"

# make_deb NAME DEPENDS: a package with one script, built with dpkg-deb.
make_deb() {
  d=$WORK_DIR/$1
  mkdir -p "$d/DEBIAN" "$d/usr/bin"
  printf '#!/bin/sh\necho "%s runs"\n' "$1" >"$d/usr/bin/$1"
  chmod 0755 "$d/usr/bin/$1"
  cat >"$d/DEBIAN/control" <<CONTROL
Package: $1
Version: 1.0
Architecture: amd64
Maintainer: pumptherm system tests <tests@pumptherm.invalid>
Depends: $2
Description: probe package of the pumptherm system test harness
 Installed offline by tests/system/apt_offline.sh.
CONTROL
  dpkg-deb --root-owner-group --build "$d" "$WORK_DIR/${1}_1.0_amd64.deb" >/dev/null ||
    fail "dpkg-deb --build $1"
}

# The libraries pumpthermd, pumptherm and the LCM tools link against (ldd + dpkg -S on the host).
make_deb pumptherm-probe "libc6, libstdc++6, libgcc-s1, libsystemd0, libfmt9, libtomlplusplus3, libmuparser2v5, libgomp1, liblcm1, libglib2.0-0, libsodium23"
cd "$WORK_DIR"
timeout 120 apt-get install -y --no-install-recommends ./pumptherm-probe_1.0_amd64.deb \
  >"$WORK_DIR/apt.log" 2>&1 || { sed 's/^/  /' "$WORK_DIR/apt.log"; fail "apt-get install ./pumptherm-probe_1.0_amd64.deb"; }
sed 's/^/  /' "$WORK_DIR/apt.log" | tail -n 4
dpkg-query -W -f='${Status}\n' pumptherm-probe | grep -q '^install ok installed$' ||
  fail "pumptherm-probe is not 'install ok installed'"
[ "$(pumptherm-probe)" = "pumptherm-probe runs" ] || fail "the installed program does not run"
echo "$T: a .deb depending on our run-time libraries installs offline"

# A dependency the base lacks cannot be fetched: apt must say so and fail.
make_deb pumptherm-probe-missing "pumptherm-no-such-package"
rc=0
timeout 120 apt-get install -y ./pumptherm-probe-missing_1.0_amd64.deb >"$WORK_DIR/apt2.log" 2>&1 || rc=$?
sed 's/^/  /' "$WORK_DIR/apt2.log" | tail -n 4
[ "$rc" -ne 0 ] || fail "apt-get installed a package whose dependency does not exist"
[ "$rc" -ne 124 ] || fail "apt-get hung (timeout) instead of failing"
grep -q 'pumptherm-no-such-package' "$WORK_DIR/apt2.log" || fail "apt's message does not name the missing dependency"
echo "$T: PASS"
