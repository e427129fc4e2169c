#!/usr/bin/env bash
# `pumptherm clear-trip` and `--version` of both commands: each bad input gives one clear line
# and the documented exit code (2), a gateway that does not answer gives exit 1. The accepted
# and refused exchanges with a gateway are ClearGateway.ClientSeesTheGatewaysSignedAnswer.
set -u
tool=$1
daemon=$2
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail=0
# shellcheck source=../common/expect.sh
source "$(dirname "${BASH_SOURCE[0]}")/../common/expect.sh"

expect 0 '^pumptherm [0-9]+\.[0-9]+\.[0-9]+$' -- "$tool" --version
expect 0 '^pumpthermd [0-9]+\.[0-9]+\.[0-9]+$' -- "$daemon" --version

head -c 32 /dev/urandom > "$tmp/clear.key"
chmod 0640 "$tmp/clear.key"
cat > "$tmp/d.toml" <<TOML
[lcm]
url = "memq://"
[alarms]
clear_lcm_sources = ["operator"]
clear_key_file = "clear.key"
clear_key_group = "$(id -gn)"
[[can]]
interface = "can0"
[[pump]]
name = "tmp1"
node_id = 1
TOML
# memq:// is this process alone: nobody answers.
expect 1 "tmp1: no answer from the gateway within 0.2 s on memq://" -- "$tool" clear-trip tmp1 -c "$tmp/d.toml" --timeout-s 0.2
expect 2 "pump 'tmp9' is not configured in $tmp/d.toml" -- "$tool" clear-trip tmp9 -c "$tmp/d.toml"
# Another host: no configuration, the URL and the key on the command line.
expect 1 "tmp1: no answer from the gateway within 0.2 s on memq://" -- "$tool" clear-trip tmp1 -c "$tmp/none.toml" --url memq:// --key "$tmp/clear.key" --timeout-s 0.2
expect 2 "nonexistent.toml: cannot open" -- "$tool" clear-trip tmp1 -c "$tmp/nonexistent.toml"
chmod 0644 "$tmp/clear.key"
expect 2 "clear.key is open to others \(mode 0644\)" -- "$tool" clear-trip tmp1 -c "$tmp/d.toml"
expect 2 "d.toml:5: key 'alarms.clear_key_file': .*clear.key is open to others \(mode 0644\)" -- "$daemon" --check-config "$tmp/d.toml"
chmod 0640 "$tmp/clear.key"
expect 0 "d.toml: OK" -- "$daemon" --check-config "$tmp/d.toml"
head -c 16 /dev/urandom > "$tmp/clear.key"
expect 2 "clear.key holds 16 bytes; a clear key is 32 random bytes" -- "$tool" clear-trip tmp1 -c "$tmp/d.toml"
sed -i '/clear_key/d' "$tmp/d.toml"
# No key and no CAN clear interface: no route, and the message names both.
expect 2 "d.toml: pump 'tmp1' is on interface 'can0', which is not in alarms.clear_can_interfaces \(empty\).*LCM clears need lcm.url and alarms.clear_key_file" -- "$tool" clear-trip tmp1 -c "$tmp/d.toml"
expect 2 "d.toml: LCM clears need lcm.url and alarms.clear_key_file" -- "$tool" clear-trip tmp1 -c "$tmp/d.toml" --via lcm
expect 0 "d.toml: OK" -- "$daemon" --check-config "$tmp/d.toml"
expect 0 "clear_lcm_sources is set but alarms.clear_key_file is not: every LCM clear will be refused" -- "$daemon" --check-config "$tmp/d.toml"
# The pump's interface among the CAN clear interfaces: the CAN route is taken (this host has no
# SocketCAN, so opening the socket is what fails; the vcan guest has no clear-trip test).
sed -i 's/^\[alarms\]$/[alarms]\nclear_can_interfaces = ["can0"]/' "$tmp/d.toml"
if [[ -d /proc/sys/net/can ]]; then
  echo "skip: this kernel has SocketCAN; the no-CAN expectation below does not apply"
else
  expect 1 "tmp1: cannot open CAN interface 'can0' to send PUMP_CLEAR: Address family not supported" -- "$tool" clear-trip tmp1 -c "$tmp/d.toml" --timeout-s 0.2
fi
exit $fail
