#!/bin/sh
# tools/pumptherm-spy without a display: with JAVA pointing at a stub that records its
# arguments, check the class path and arguments it hands to java, in the build tree and in an
# installed layout, and its errors.
#   spy_launcher_test.sh BUILD_DIR
set -eu
build_dir=$(CDPATH= cd -- "$1" && pwd)
source_dir=$(CDPATH= cd -- "$(dirname -- "$0")/../.." && pwd)
work=$(mktemp -d /tmp/pumptherm-spy-launcher.XXXXXX)
trap 'rm -rf "$work"' EXIT
failures=0
fail() {
  echo "FAIL: $*" >&2
  failures=$((failures + 1))
}

# The stub writes one argument per line.
cat > "$work/java" << 'EOF'
#!/bin/sh
for arg in "$@"; do printf '%s\n' "$arg"; done > "$STUB_OUT"
EOF
chmod +x "$work/java"
export JAVA="$work/java" STUB_OUT="$work/args"
unset PUMPTHERM_LCM_TYPES_JAR LCM_JAR JCHART2D_JAR || true

# Prints the -cp value java received.
classpath() { sed -n '/^-cp$/{n;p;}' "$work/args"; }

# 1. Build tree: the copy in <build>/tools uses <build>/protocol/lcm/pumptherm_lcm_types.jar;
#    arguments pass through unchanged, spaces included; the JDK 17-hostile -Xincgc is absent.
build_jar=$build_dir/protocol/lcm/pumptherm_lcm_types.jar
[ -f "$build_jar" ] || fail "$build_jar not built"
"$build_dir/tools/pumptherm-spy" --lcm-url='udpm://239.255.76.67:7667?ttl=0' "two words"
cp=$(classpath)
case "$cp" in
  /usr/share/java/lcm.jar:/usr/share/java/jchart2d.jar:*/protocol/lcm/pumptherm_lcm_types.jar) ;;
  *) fail "build tree class path: $cp" ;;
esac
[ "$(readlink -f "${cp##*:}")" = "$(readlink -f "$build_jar")" ] || fail "build tree jar: ${cp##*:}"
case ":$cp:" in
  *:*/protocol/lcm/pumptherm_spy_plugin.jar:*) ;;
  *) fail "build tree class path lacks the plugin jar: $cp" ;;
esac
tail -n 3 "$work/args" > "$work/tail"
printf '%s\n' lcm.spy.Spy '--lcm-url=udpm://239.255.76.67:7667?ttl=0' 'two words' | cmp -s - "$work/tail" ||
  fail "arguments not passed through: $(cat "$work/tail")"
grep -q -x -- -Xincgc "$work/args" && fail "-Xincgc passed to java"
# The plugin's own subscription gets lcm-spy's URL, in each of lcm-spy's spellings.
grep -q -x -- '-Dpumptherm.spy.lcm_url=udpm://239.255.76.67:7667?ttl=0' "$work/args" ||
  fail "URL not handed to the plugin: $(cat "$work/args")"
"$build_dir/tools/pumptherm-spy" -l 'udpm://239.255.76.67:7668?ttl=0'
grep -q -x -- '-Dpumptherm.spy.lcm_url=udpm://239.255.76.67:7668?ttl=0' "$work/args" || fail "-l URL not handed to the plugin"
# --url (the name `pumptherm watch` and `clear-trip` use) becomes lcm-spy's --lcm-url=URL.
for form in "--url udpm://239.255.76.67:7669?ttl=0" "--url=udpm://239.255.76.67:7669?ttl=0"; do
  # shellcheck disable=SC2086  # the form is two words or one, on purpose
  "$build_dir/tools/pumptherm-spy" $form "two words"
  tail -n 3 "$work/args" > "$work/tail"
  printf '%s\n' lcm.spy.Spy '--lcm-url=udpm://239.255.76.67:7669?ttl=0' 'two words' | cmp -s - "$work/tail" ||
    fail "$form not passed as --lcm-url: $(cat "$work/tail")"
  grep -q -x -- '-Dpumptherm.spy.lcm_url=udpm://239.255.76.67:7669?ttl=0' "$work/args" ||
    fail "$form not handed to the plugin"
done

# 2. Installed layout: <prefix>/bin/pumptherm-spy and <prefix>/share/pumptherm/java/<jar>.
mkdir -p "$work/prefix/bin" "$work/prefix/share/pumptherm/java"
cp "$source_dir/tools/pumptherm-spy" "$work/prefix/bin/"
cp "$build_jar" "$work/prefix/share/pumptherm/java/"
"$work/prefix/bin/pumptherm-spy" 2> "$work/err"
grep -q "pumptherm_spy_plugin.jar not found" "$work/err" || fail "no warning without the plugin jar: $(cat "$work/err")"
cp=$(classpath)
[ "$(readlink -f "${cp##*:}")" = "$(readlink -f "$work/prefix/share/pumptherm/java/pumptherm_lcm_types.jar")" ] ||
  fail "installed class path: $cp"

# 3. The jar holds a class for every .lcm file (listed with the JDK's jar tool).
jar_listing=$(jar tf "$build_jar")
for lcm in "$source_dir"/protocol/lcm/*.lcm; do
  type=$(basename "$lcm" .lcm)
  printf '%s\n' "$jar_listing" | grep -q -x "pumptherm/$type.class" || fail "pumptherm/$type.class missing from the jar"
done

# 4. Errors: no jar found, or an override naming a missing file: exit 2 and a message.
mkdir -p "$work/nowhere"
cp "$source_dir/tools/pumptherm-spy" "$work/nowhere/"
if "$work/nowhere/pumptherm-spy" 2> "$work/err"; then fail "ran without a jar"; fi
grep -q "pumptherm_lcm_types.jar not found" "$work/err" || fail "no-jar message: $(cat "$work/err")"
status=0
PUMPTHERM_LCM_TYPES_JAR=$work/missing.jar "$build_dir/tools/pumptherm-spy" 2> "$work/err" || status=$?
[ "$status" = 2 ] || fail "missing override: exit $status"
grep -q "missing.jar: no such file" "$work/err" || fail "missing override message: $(cat "$work/err")"
status=0
LCM_JAR=$work/missing-lcm.jar "$build_dir/tools/pumptherm-spy" 2> "$work/err" || status=$?
[ "$status" = 2 ] || fail "missing lcm.jar: exit $status"

if [ "$failures" -gt 0 ]; then
  exit 1
fi
echo "pumptherm-spy launcher: build tree, installed layout, jar contents and errors OK"
