#!/usr/bin/env bash
# The Debian packages as built (`cmake --build build --target deb`): pumptherm (the daemon) and
# pumptherm-tools: what each holds, that together they hold everything `cmake --install` installs,
# their control fields (the daemon's Depends has none of the tools' numerical libraries), the
# daemon's conffiles and maintainer scripts, and lintian's verdict on both.
#   deb_check.sh BUILD_DIR VERSION PACKAGING_MD
# Fails on any lintian error, and on any lintian warning that docs/packaging.md does not list
# (the page gives each one's reason). Skips (77) when lintian is not installed.
set -u
build=$1
version=$2
doc=$3
fail=0
deb=$(ls "$build"/pumptherm_"$version"_*.deb 2>/dev/null | head -n 1)
tools_deb=$(ls "$build"/pumptherm-tools_"$version"_*.deb 2>/dev/null | head -n 1)
[[ -n $deb ]] || { echo "FAIL: no $build/pumptherm_${version}_*.deb (build the target deb)"; exit 1; }
[[ -n $tools_deb ]] || { echo "FAIL: no $build/pumptherm-tools_${version}_*.deb (build the target deb)"; exit 1; }
echo "packages: $deb ($(du -k "$deb" | cut -f1) KiB), $tools_deb ($(du -k "$tools_deb" | cut -f1) KiB)"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

contents() { dpkg-deb --contents "$1" | awk '{ print $6 }' | sed 's|^\./|/|; s|/$||'; }
contents "$deb" > "$tmp/files"
contents "$tools_deb" > "$tmp/tools_files"
holds() {  # holds LIST_FILE PACKAGE PATH...
  local list=$1 pkg=$2; shift 2
  for f in "$@"; do
    grep -qxF "$f" "$list" && echo "ok: $pkg holds $f" || { echo "FAIL: $f is not in $pkg"; fail=1; }
  done
}
holds "$tmp/files" pumptherm /usr/sbin/pumpthermd \
  /lib/systemd/system/pumpthermd.service /etc/pumptherm/pumpthermd.toml.example \
  /usr/share/pumptherm/dbc/pumptherm.dbc /usr/share/pumptherm/dbc/mapping_pumptherm.toml \
  /usr/share/pumptherm/models/tmp-generic.toml /usr/share/pumptherm/motors/han2019-tmp.toml \
  /usr/share/pumptherm/examples/pumpthermd-demo.toml \
  /usr/share/man/man8/pumpthermd.8.gz /usr/share/man/man5/pumpthermd.toml.5.gz \
  /usr/share/doc/pumptherm/copyright /usr/share/doc/pumptherm/changelog.gz \
  /usr/share/doc/pumptherm/operator-guide.md
holds "$tmp/tools_files" pumptherm-tools /usr/bin/pumptherm /usr/bin/pumptherm-spy /usr/bin/pumptherm-lcm-demo \
  /usr/share/pumptherm/java/pumptherm_lcm_types.jar /usr/share/pumptherm/java/pumptherm_spy_plugin.jar \
  /usr/share/pumptherm/scenarios/demo.toml \
  /usr/share/man/man1/pumptherm.1.gz /usr/share/man/man1/pumptherm-spy.1.gz \
  /usr/share/doc/pumptherm-tools/copyright /usr/share/doc/pumptherm-tools/changelog.gz
# No file in both (dpkg would refuse the second), and together everything a plain install has.
nondirs() { dpkg-deb --contents "$1" | awk '$1 !~ /^d/ { print $6 }' | sed 's|^\./|/|' | sort; }
both=$(comm -12 <(nondirs "$deb") <(nondirs "$tools_deb"))
[[ -z $both ]] && echo "ok: no file is in both packages" ||
  { echo "FAIL: in both packages:"; echo "$both" | sed 's/^/    /'; fail=1; }
DESTDIR="$tmp/all" cmake --install "$build" --prefix /usr >/dev/null 2>&1 ||
  { echo "FAIL: cmake --install of $build"; fail=1; }
(cd "$tmp/all" && find . -type f | sed 's|^\./|/|' | sort) > "$tmp/installed"
missing=$(comm -23 "$tmp/installed" <(sort -u "$tmp/files" "$tmp/tools_files"))
if [[ -n $missing ]]; then
  echo "FAIL: installed by cmake --install but in neither package (give the install rule a COMPONENT):"
  echo "$missing" | sed 's/^/    /'
  fail=1
else
  echo "ok: every file of cmake --install ($(wc -l < "$tmp/installed")) is in one of the packages"
fi
# Every shipped model and motor of the source tree is in the package.
src=$(cd "$(dirname "$0")/../.." && pwd)
for f in "$src"/estimators/models/*.toml "$src"/estimators/motors/*.toml; do
  kind=$(basename "$(dirname "$f")")
  grep -qxF "/usr/share/pumptherm/$kind/$(basename "$f")" "$tmp/files" ||
    { echo "FAIL: $kind/$(basename "$f") is not in the package"; fail=1; }
done
# Nothing under /usr/local, nothing from the build tree.
if grep -E '^/usr/local|/build' "$tmp/files"; then echo "FAIL: paths above do not belong in a package"; fail=1; fi

# Control: dependencies computed by dpkg-shlibdeps (versioned library packages), not hand-made.
dpkg-deb --field "$deb" Depends > "$tmp/depends"
echo "Depends: $(cat "$tmp/depends")"
# Every library package our binaries link, and versions where the library's symbols file gives
# one (libsystemd0's minimum is older than any release; liblcm1 has no symbols file).
for lib in libc6 libstdc++6 libgcc-s1 libsystemd0 libfmt9 libtomlplusplus3 libmuparser2v5 liblcm1 libsodium23; do
  tr ',' '\n' < "$tmp/depends" | sed 's/^ *//; s/ .*//' | grep -qxF "$lib" ||
    { echo "FAIL: Depends lacks $lib"; fail=1; }
done
grep -qE '(^|, )libc6 \(>= [0-9.]+\)' "$tmp/depends" ||
  { echo "FAIL: libc6 is not versioned: Depends was not computed by dpkg-shlibdeps"; fail=1; }
for lib in libceres libgoogle-glog libatlas liblapack libcholmod libspqr libcxsparse; do
  grep -q "$lib" "$tmp/depends" && { echo "FAIL: the daemon's Depends has $lib (only the tools need it)"; fail=1; }
done
tools_depends=$(dpkg-deb --field "$tools_deb" Depends)
echo "pumptherm-tools Depends: $tools_depends"
echo "$tools_depends" | grep -qE "(^|, )pumptherm \(= $version\)" ||
  { echo "FAIL: pumptherm-tools does not depend on pumptherm (= $version)"; fail=1; }
echo "$tools_depends" | grep -qE '(^|, )libc6 \(>= [0-9.]+\)' ||
  { echo "FAIL: pumptherm-tools' Depends was not computed by dpkg-shlibdeps"; fail=1; }
echo "pumptherm-tools Recommends: $(dpkg-deb --field "$tools_deb" Recommends)"

# Conffiles: the example configuration only (the operator's pumpthermd.toml is not dpkg's).
dpkg-deb --ctrl-tarfile "$deb" | tar -xf - -C "$tmp" ./conffiles ./postinst ./prerm ./postrm 2>/dev/null
if [[ "$(cat "$tmp/conffiles" 2>/dev/null)" == "/etc/pumptherm/pumpthermd.toml.example" ]]; then
  echo "ok: conffiles: /etc/pumptherm/pumpthermd.toml.example"
else
  echo "FAIL: conffiles is '$(cat "$tmp/conffiles" 2>/dev/null)'"; fail=1
fi
for s in postinst prerm postrm; do
  [[ -x $tmp/$s ]] && sh -n "$tmp/$s" && echo "ok: $s present, executable, parses" ||
    { echo "FAIL: maintainer script $s missing, not executable or not sh"; fail=1; }
done
# The unit waits for the operator's configuration.
dpkg-deb --fsys-tarfile "$deb" | tar -xOf - ./lib/systemd/system/pumpthermd.service |
  grep -qxF 'ConditionPathExists=/etc/pumptherm/pumpthermd.toml' &&
  echo "ok: the unit has ConditionPathExists=/etc/pumptherm/pumpthermd.toml" ||
  { echo "FAIL: the unit does not wait for /etc/pumptherm/pumpthermd.toml"; fail=1; }

# lintian
if ! command -v lintian > /dev/null; then
  echo "SKIP: lintian is not installed (tools/setup.sh installs it); the checks above ran"
  [[ $fail == 0 ]] && exit 77 || exit 1
fi
lintian --no-cfg --display-info "$deb" "$tools_deb" 2>&1 | grep -v "running with root privileges" > "$tmp/lintian"
sed 's/^/  lintian: /' "$tmp/lintian"
if grep -q '^E: ' "$tmp/lintian"; then echo "FAIL: lintian reports errors"; fail=1; else echo "ok: lintian: no errors"; fi
# Each warning's tag must appear in docs/packaging.md (with its reason there).
for tag in $(awk '/^W: / { print $3 }' "$tmp/lintian" | sort -u); do
  grep -qF -- "\`$tag\`" "$doc" && echo "ok: lintian warning $tag is listed in docs/packaging.md" ||
    { echo "FAIL: lintian warning $tag is not listed in $(basename "$doc") with its reason"; fail=1; }
done
exit $fail
