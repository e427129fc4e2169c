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
# The service refuses a configuration with exit 78 (EX_CONFIG), which the unit does not restart.
expect 78 "bad.toml:2: key 'gateway.heartbeat_period_s': expected a number" -- "$bin" --config "$tmp/bad.toml"
expect 2 "bad.toml:2: key 'gateway.heartbeat_period_s'" -- "$bin" --check-config "$tmp/bad.toml"
grep -qx 'RestartPreventExitStatus=78' "$data/../../systemd/pumpthermd.service" ||
  { echo "FAIL: the unit does not stop restarting on exit 78"; fail=1; }
# --check-config refuses what the service refuses (no interface) and what would run wrong (no pump).
: > "$tmp/empty.toml"
expect 2 "empty.toml: no \[\[can\]\] interface: the service would not start" -- "$bin" --check-config "$tmp/empty.toml"
expect 78 "empty.toml: no \[\[can\]\] interface configured" -- "$bin" --config "$tmp/empty.toml"
printf '[[can]]\ninterface = "pt_nosuch0"\n' > "$tmp/missing.toml"
expect 2 "missing.toml: no \[\[pump\]\]: the gateway would estimate nothing" -- "$bin" --check-config "$tmp/missing.toml"
# A missing interface: "cannot find it" where the kernel has CAN, "no SocketCAN" where not.
expect 1 "interface 'pt_nosuch0': cannot (find it|open a CAN socket)" -- "$bin" --config "$tmp/missing.toml"
expect 1 "nonexistent.log: cannot read the log: No such file or directory" -- "$bin" -r "$tmp/nonexistent.log"
# A log that is a directory, empty, or nothing but junk: a non-zero exit naming the file and why.
mkdir "$tmp/logdir"
expect 1 "logdir: is a directory, not a candump log" -- "$bin" -r "$tmp/logdir"
: > "$tmp/empty.log"
expect 1 "empty.log: empty: no frame to run on" -- "$bin" -r "$tmp/empty.log"
printf 'hello\n(12) can0\n# comment\n' > "$tmp/junk.log"
expect 1 "junk.log: no frame to run on in 3 lines: 2 not candump lines, 0 without a timestamp, 1 blank or comments" -- "$bin" -r "$tmp/junk.log"
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
# Keys of the frame layout and of a pump are named with their own line; a wrong node lists the
# model's nodes.
one_pump() {  # one_pump FILE DBC [PUMP KEY LINE]
  printf '[[can]]\ninterface = "can0"\n[dbc]\nfile = "%s"\nmapping = "mapping_pumptherm.toml"\n[[pump]]\nname = "p"\nnode_id = 1\n%s\n' "$2" "${3:-}" > "$1"
}
one_pump "$tmp/nomap.toml" pumptherm.dbc
sed -i 's/mapping_pumptherm.toml/nosuch.toml/' "$tmp/nomap.toml"
expect 2 "nomap.toml:5: key 'dbc.mapping': 'nosuch.toml': no such dbc file" -- "$bin" --check-config "$tmp/nomap.toml"
one_pump "$tmp/node.toml" pumptherm.dbc 'measured_node = "housing"'
expect 2 "node.toml:9: key 'pump\[0\].measured_node': 'housing' is not a node with heat capacity of model tmp-generic \(its nodes: frame, stator, winding, rotor\)" -- "$bin" --check-config "$tmp/node.toml"
# A DBC cut before its attributes: every output would go out as raw 0 while unknown and at 1 Hz.
dbc=$data/../../protocol/pumptherm.dbc
grep -v '^BA_' "$dbc" > "$tmp/cut.dbc"
one_pump "$tmp/cut.toml" cut.dbc
expect 2 "cut.toml:4: key 'dbc.file': .*cut.dbc: [0-9]+ output signals without a \"not available\" raw value \(attribute GenSigSNA\), GW_ALARM.AlarmLevel \(outputs.alarm_level\), .* and [0-9]+ more: while unknown" -- "$bin" --check-config "$tmp/cut.toml"
expect 78 "cut.toml:4: key 'dbc.file'" -- "$bin" --config "$tmp/cut.toml"
grep -v '^BA_ "GenMsgCycleTime"' "$dbc" > "$tmp/cycle.dbc"
one_pump "$tmp/cycle.toml" cycle.dbc
expect 2 "cycle.toml:4: key 'dbc.file': .*cycle.dbc: output messages GW_ALARM, .* have no cycle time \(attribute GenMsgCycleTime, neither its BA_ nor a default above 0\): the gateway would send them every 1 s" -- "$bin" --check-config "$tmp/cycle.toml"
# An override of a message the gateway does not send would change nothing.
one_pump "$tmp/period.toml" pumptherm.dbc
printf '[output_periods_s]\nGW_TEMP_A = 0.5\n' >> "$tmp/period.toml"
expect 2 "period.toml:11: key 'output_periods_s.GW_TEMP_A': GW_TEMP_A is not a message the gateway sends \(its output messages: GW_ALARM, " -- "$bin" --check-config "$tmp/period.toml"
# A configuration that is a directory says so.
expect 2 "$tmp: is a directory, not a configuration file" -- "$bin" --check-config "$tmp"
# A path that exists is a path, whatever the case of its extension.
cp "$dbc" "$tmp/Upper.DBC"
one_pump "$tmp/upper.toml" Upper.DBC
expect 0 "upper.toml: OK \(1 interface, 1 pump\)" -- "$bin" --check-config "$tmp/upper.toml"

# The example configuration shipped in systemd/ is valid.
expect 0 "pumpthermd.toml: OK \(1 interface, 1 pump\)" -- "$bin" --check-config "$data/../../systemd/pumpthermd.toml"
exit $fail
