#!/usr/bin/env bash
# The shipped example configuration (systemd/pumpthermd.toml, installed as
# /etc/pumptherm/pumpthermd.toml.example) lists every key the configuration reader accepts, set
# or commented, and docs/daemon.md's table names each; the example itself passes --check-config.
# The reader's keys are taken from daemon/config.cpp: each is read through TableReader, as
# r.Number("key"...), r.String("key"...), r.Table("key") and so on.
#   example_config_keys_test.sh PUMPTHERMD SOURCE_DIR
set -u
pumpthermd=$1
src=$2
example=$src/systemd/pumpthermd.toml
fail=0
keys=$(grep -oE 'r\.[A-Za-z]+\("[A-Za-z_0-9]+"' "$src/daemon/config.cpp" | sed 's/.*("//; s/"//' | sort -u)
[ -n "$keys" ] || { echo "FAIL: no keys found in daemon/config.cpp"; exit 1; }
n=0
for k in $keys; do
  n=$((n + 1))
  # A key line ("key = ...", maybe commented) or a table header naming it ("[...key]").
  grep -qE "(^|[{ ,#])$k *=|^#? *\[.*\b$k\]" "$example" || { echo "FAIL: the example lacks '$k'"; fail=1; }
  grep -qF "$k" "$src/docs/daemon.md" || { echo "FAIL: docs/daemon.md does not name '$k'"; fail=1; }
done
"$pumpthermd" --check-config "$example" || { echo "FAIL: the example does not pass --check-config"; fail=1; }
[ "$fail" -eq 0 ] && echo "PASS: the example lists all $n keys of the reader, each documented"
exit "$fail"
