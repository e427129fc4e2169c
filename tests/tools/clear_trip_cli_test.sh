#!/usr/bin/env bash
# `pumptherm keygen`, `pumptherm clear-trip` and `--version` of both commands: each bad input
# gives one clear line and the documented exit code (2), a gateway that does not answer gives
# exit 1. The accepted and refused exchanges with a gateway are
# ClearGateway.ClientSeesTheGatewaysSignedAnswer and tests/daemon/clear_e2e_test.sh.
set -u
tool=$1
daemon=$2
tmp=$(mktemp -d)
chmod 0700 "$tmp"
trap 'chmod -R u+w "$tmp"; rm -rf "$tmp"' EXIT
fail=0
# shellcheck source=../common/expect.sh
source "$(dirname "${BASH_SOURCE[0]}")/../common/expect.sh"

expect 0 '^pumptherm [0-9]+\.[0-9]+\.[0-9]+$' -- "$tool" --version
expect 0 '^pumpthermd [0-9]+\.[0-9]+\.[0-9]+$' -- "$daemon" --version

# Keys as the operator guide makes them: the operator's own, the gateway's.
expect 0 "^key ID [0-9a-f]{16}$" -- "$tool" keygen "$tmp/keys/alice.key" --name alice --make-dir
expect 0 "set gateway.signing_key_file = \"$tmp/gateway.key\"" -- "$tool" keygen "$tmp/gateway.key" --name gw
expect 2 "a key is there already; keygen never replaces one" -- "$tool" keygen "$tmp/gateway.key" --name gw
expect 2 "name is required" -- "$tool" keygen "$tmp/nameless.key"
[[ "$(stat -c %a "$tmp/keys/alice.key") $(stat -c %a "$tmp/keys")" == "600 700" ]] ||
  { echo "FAIL: modes $(stat -c %a "$tmp/keys/alice.key") $(stat -c %a "$tmp/keys"), want 600 700"; fail=1; }
pub=$(cut -d' ' -f1 "$tmp/keys/alice.key.pub")

cat > "$tmp/d.toml" <<TOML
[gateway]
signing_key_file = "gateway.key"
[lcm]
url = "memq://"
[alarms]
[[alarms.clear_operators]]
name = "alice"
public_key = "$pub"
[[can]]
interface = "can0"
[[pump]]
name = "tmp1"
node_id = 1
TOML
expect 0 "d.toml: OK" -- "$daemon" --check-config "$tmp/d.toml"
key=(--key "$tmp/keys/alice.key")
# memq:// is this process alone: nobody answers.
expect 1 "tmp1: no answer from gateway 'pumptherm' within 0.2 s on memq://" -- "$tool" clear-trip tmp1 -c "$tmp/d.toml" "${key[@]}" --timeout-s 0.2
expect 2 "pump 'tmp9' is not configured in $tmp/d.toml" -- "$tool" clear-trip tmp9 -c "$tmp/d.toml" "${key[@]}"
# Another host: no configuration; the URL, the gateway's name and public key on the command line.
expect 1 "tmp1: no answer from gateway 'gw' within 0.2 s on memq://" -- "$tool" clear-trip tmp1 -c "$tmp/none.toml" --url memq:// --gateway gw --gateway-key "$tmp/gateway.key.pub" "${key[@]}" --timeout-s 0.2
expect 2 "nonexistent.toml: cannot open" -- "$tool" clear-trip tmp1 -c "$tmp/nonexistent.toml"
expect 2 "nokey.key: No such file|cannot stat .*nokey.key" -- "$tool" clear-trip tmp1 -c "$tmp/d.toml" --key "$tmp/nokey.key"
# The operator's key: owner, mode, folder, contents.
chmod 0644 "$tmp/keys/alice.key"
expect 2 "alice.key is open to its group or others \(mode 0644\)" -- "$tool" clear-trip tmp1 -c "$tmp/d.toml" "${key[@]}"
chmod 0600 "$tmp/keys/alice.key"
chmod 0777 "$tmp/keys"
expect 2 "alice.key is in .*keys, which others may write \(mode 0777\)" -- "$tool" clear-trip tmp1 -c "$tmp/d.toml" "${key[@]}"
chmod 0700 "$tmp/keys"
head -c 32 /dev/zero > "$tmp/keys/zero.key"
chmod 0600 "$tmp/keys/zero.key"
expect 2 "zero.key: the key is all zero bytes: not a key" -- "$tool" clear-trip tmp1 -c "$tmp/d.toml" --key "$tmp/keys/zero.key"
head -c 16 /dev/urandom > "$tmp/keys/short.key"
chmod 0600 "$tmp/keys/short.key"
expect 2 "short.key holds 16 bytes; a secret key is 32 bytes" -- "$tool" clear-trip tmp1 -c "$tmp/d.toml" --key "$tmp/keys/short.key"
# The gateway's key: checked by the daemon and --check-config, naming file, line and key.
chmod 0644 "$tmp/gateway.key"
expect 2 "d.toml:2: key 'gateway.signing_key_file': .*gateway.key is open to its group or others \(mode 0644\)" -- "$daemon" --check-config "$tmp/d.toml"
chmod 0600 "$tmp/gateway.key"
expect 0 "d.toml: OK" -- "$daemon" --check-config "$tmp/d.toml"
sed -i '/signing_key_file/d' "$tmp/d.toml"
# No gateway key and no CAN clear interface: no route, and the message names both.
expect 2 "d.toml: pump 'tmp1' is on interface 'can0', which is not in alarms.clear_can_interfaces \(empty\).*LCM clears need lcm.url and gateway.signing_key_file" -- "$tool" clear-trip tmp1 -c "$tmp/d.toml"
expect 2 "d.toml: LCM clears need lcm.url and gateway.signing_key_file" -- "$tool" clear-trip tmp1 -c "$tmp/d.toml" --via lcm
expect 0 "d.toml: OK" -- "$daemon" --check-config "$tmp/d.toml"
expect 0 "operators may clear over LCM but gateway.signing_key_file is not set: every LCM clear will be refused" -- "$daemon" --check-config "$tmp/d.toml"
# The pump's interface among the CAN clear interfaces: the CAN route is taken (this host has no
# SocketCAN, so opening the socket is what fails; the vcan guest has no clear-trip test).
sed -i 's/^\[alarms\]$/[alarms]\nclear_can_interfaces = ["can0"]/' "$tmp/d.toml"
if [[ -d /proc/sys/net/can ]]; then
  echo "skip: this kernel has SocketCAN; the no-CAN expectation below does not apply"
else
  expect 1 "tmp1: cannot open CAN interface 'can0' to send PUMP_CLEAR: Address family not supported" -- "$tool" clear-trip tmp1 -c "$tmp/d.toml" --timeout-s 0.2
fi
exit $fail
