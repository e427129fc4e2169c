#!/usr/bin/env bash
# pumpthermd's command line: each bad input gives one clear line and the documented exit code;
# the offline run of the bundled recording prints the per-ID counts the log really holds.
set -u
bin=$1
data=$2
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail=0
# shellcheck source=../common/expect.sh
source "$(dirname "${BASH_SOURCE[0]}")/../common/expect.sh"

printf '[gateway]\nheartbeat_period_s = "fast"\n' > "$tmp/bad.toml"
expect 2 "bad.toml:2: key 'gateway.heartbeat_period_s': expected a number" -- "$bin" --config "$tmp/bad.toml"
expect 2 "bad.toml:2: key 'gateway.heartbeat_period_s'" -- "$bin" --check-config "$tmp/bad.toml"
printf '[[can]]\ninterface = "pt_nosuch0"\n' > "$tmp/missing.toml"
expect 0 "missing.toml: OK \(1 interface, 0 pumps\)" -- "$bin" --check-config "$tmp/missing.toml"
# A missing interface: "cannot find it" where the kernel has CAN, "no SocketCAN" where not.
expect 1 "interface 'pt_nosuch0': cannot (find it|open a CAN socket)" -- "$bin" --config "$tmp/missing.toml"
expect 1 "nonexistent.log: cannot read the log: No such file or directory" -- "$bin" -r "$tmp/nonexistent.log"
expect 2 "nothing to do" -- "$bin"

# Offline counts equal what the log holds, counted independently here with awk.
"$bin" -r "$data/skeleton.log" > "$tmp/offline.txt" 2> "$tmp/offline.err" || { echo "FAIL: offline run"; fail=1; }
awk '{split($3, a, "#"); n[$2 " " a[1]]++} END {for (k in n) print k, n[k]}' "$data/skeleton.log" | sort > "$tmp/want.txt"
awk 'NR > 2 {print $1, $2, $3}' "$tmp/offline.txt" | sort > "$tmp/got.txt"
if diff -u "$tmp/want.txt" "$tmp/got.txt"; then echo "ok: offline per-ID counts match the log ($(wc -l < "$tmp/got.txt") IDs)"; else echo "FAIL: offline counts differ"; fail=1; fi
grep -q "2210 frames, 5 CAN IDs, 0 malformed lines skipped" "$tmp/offline.txt" || { echo "FAIL: summary line"; cat "$tmp/offline.txt"; fail=1; }

# Malformed lines are reported with file:line:column and counted; the run goes on.
{ head -n 5 "$data/skeleton.log"; echo "(1.0) can0 1G1#00"; tail -n 5 "$data/skeleton.log"; } > "$tmp/bad.log"
expect 0 "bad.log:6:13: expected a hexadecimal CAN ID; line skipped" -- "$bin" -r "$tmp/bad.log"
"$bin" -r "$tmp/bad.log" 2>/dev/null | grep -q "10 frames, .* 1 malformed lines skipped" || { echo "FAIL: bad line not counted"; fail=1; }
# From stdin, as in `candump -L can0 | pumpthermd -r -`.
"$bin" -r - < "$data/skeleton.log" | grep -q "<stdin>: 2210 frames" || { echo "FAIL: stdin"; fail=1; }
# A DBC with a malformed statement: --check-config reports the warning (file:line:column) and
# accepts the configuration, since the rest of the DBC loads.
cp "$data/../../protocol/pumptherm.dbc" "$tmp/w.dbc"
printf 'BO_ 3221225763 BIT30: 8 Gateway\n SG_ X : 0|8@1+ (1,0) [0|0] "" Monitor\n' >> "$tmp/w.dbc"
bad_line=$(($(wc -l < "$data/../../protocol/pumptherm.dbc") + 1))
printf '[[can]]\ninterface = "can0"\n[dbc]\nfile = "w.dbc"\nmapping = "mapping_pumptherm.toml"\n[[pump]]\nname = "p"\nnode_id = 0\ninterface = "can0"\nmotor = "han2019-tmp"\nthermal_model = "tmp-generic"\nmeasured_node = "frame"\n' > "$tmp/w.toml"
expect 0 "warning: .*w.dbc:$bad_line:1: extended message ID 0x40000123 above 29 bits" -- "$bin" --check-config "$tmp/w.toml"
expect 0 "w.toml: OK \(1 interface, 1 pump\)" -- "$bin" --check-config "$tmp/w.toml"
# The example configuration shipped in systemd/ is valid.
expect 0 "pumpthermd.toml: OK \(1 interface, 1 pump\)" -- "$bin" --check-config "$data/../../systemd/pumpthermd.toml"
exit $fail
