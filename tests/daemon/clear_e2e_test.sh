#!/usr/bin/env bash
# Signed alarm clears against a live pumpthermd, end to end, as an operator and an attacker
# would meet them (docs/threat-model.md): LCM over udpm:// in network namespaces made here (the
# multicast stays inside them), SocketCAN stood in for by a preloaded shim (this kernel has no
# CAN: can_shim.so, can_bus.py), the operator's `pumptherm clear-trip` and `keygen`, and an
# attacker's tool (lcm_clear_tool: capture, replay, flood).
#
#   clear_e2e_test.sh BUILD_DIR SOURCE_DIR CASE...
#
# CASE: clear (a signed clear over udpm, its journal line escaped), kill9 (kill -9 right after
# the client saw ACCEPTED, then a replay; six runs, and one killed inside the safety write),
# cross (a clear captured for one gateway replayed onto another), lan (a clear from a second
# namespace over a veth refused in the kernel, taken once the interface is listed), lost (the
# safety state deleted or damaged: latched, and a recorded clear cannot replay), flood (20 000
# forged clears per second for 10 s with a legitimate clear inside: every output frame on time,
# one summary line per source), readers (`pumptherm watch --gateway-key` tells a forger's phantom
# pump from the gateway's).
# Needs root (ip netns). Exits 77 (skip) without it, 1 on failure.
set -u
build=$(cd "$1" && pwd)
src=$(cd "$2" && pwd)
shift 2
cases=("$@")

[ "$(id -u)" -eq 0 ] || { echo "SKIP: needs root for ip netns"; exit 77; }
tmp=$(mktemp -d /tmp/pumptherm-e2e-XXXXXX)
chmod 0700 "$tmp"
ns=ptA$$
nsb=ptB$$
pids=()
fail=0
cleanup() {
  for p in "${pids[@]}"; do kill -9 "$p" 2>/dev/null; done
  ip netns del "$ns" 2>/dev/null
  ip netns del "$nsb" 2>/dev/null
  rm -rf "$tmp"
}
trap cleanup EXIT
ip netns add "$ns" 2>/dev/null || { echo "SKIP: ip netns add failed"; exit 77; }
ip -n "$ns" link set lo up
ip -n "$ns" link set lo multicast on
ip -n "$ns" route add 224.0.0.0/4 dev lo
# The shim's Unix datagram sockets queue 10 datagrams by default: room for the bus's pauses.
ip netns exec "$ns" sysctl -q -w net.unix.max_dgram_qlen=4096 || true

pumptherm=$build/tools/pumptherm
daemon=$build/daemon/pumpthermd
tool=$build/tests/daemon/lcm_clear_tool
shim=$build/tests/daemon/libcan_shim.so
url='udpm://239.255.76.67:7667?ttl=0'
in_ns() { ip netns exec "$ns" "$@"; }
failed() { echo "FAIL: $*"; fail=1; }
say() { echo "--- $*"; }

# Keys, as the operator guide makes them: alice's own, and one per gateway.
alice_id=$("$pumptherm" keygen "$tmp/alice.key" --name alice | sed -n 's/^key ID //p')
[ -n "$alice_id" ] || { echo "FAIL: keygen"; exit 1; }
mallory_id=$("$pumptherm" keygen "$tmp/mallory.key" --name mallory | sed -n 's/^key ID //p')
"$pumptherm" keygen "$tmp/hall1.key" --name hall1 >/dev/null
"$pumptherm" keygen "$tmp/hall2.key" --name hall2 >/dev/null
alice_pub=$(cut -d' ' -f1 "$tmp/alice.key.pub")

# config DIR NAME PREFIX [EXTRA_LCM_LINES]: a gateway with three pumps on can0 (the vcan
# pipeline's recording), alice listed, its state in DIR/state.
config() {
  local dir=$1 name=$2 prefix=$3 lcm_extra=${4:-}
  mkdir -p "$dir/state" "$dir/can"
  cat >"$dir/d.toml" <<TOML
[gateway]
name = "$name"
heartbeat_period_s = 1.0
status_period_s = 0.5
state_directory = "$dir/state"
signing_key_file = "$tmp/$name.key"
[lcm]
url = "${LCM_URL:-$url}"
channel_prefix = "$prefix"
$lcm_extra
[alarms]
hold_s = 2.0
[alarms.levels]
winding = { warning_degC = 100.0, trip_degC = 120.0 }
[[alarms.clear_operators]]
name = "alice"
public_key = "$alice_pub"
[[can]]
interface = "can0"
rx_buffer_bytes = 0
TOML
  for n in 1 2 3; do
    printf '[[pump]]\nname = "pump%s"\nnode_id = %s\nmeasured_node = "frame"\nframe_sensor_lag_s = 30.0\n' \
      "$n" "$n" >>"$dir/d.toml"
  done
}

# latch DIR: a safety state with pump1's winding trip latched (as a trip leaves it).
latch() {
  python3 - "$1/state/safety.toml" <<'PY'
import hashlib, sys
body = ('# written by clear_e2e_test.sh\nversion = 1\nrefused_up_to_us = 0\n'
        '[pump.pump1]\nlatched_trip_nodes = [ "winding" ]\nlatched_trip_values_degC = [ 130.0 ]\n'
        '[clear_counters]\n')
digest = hashlib.blake2b(body.encode(), digest_size=32).hexdigest()
open(sys.argv[1], 'w').write(body + '# blake2b-256 ' + digest + '\n')
PY
}

# start DIR [REPLAY_LOG]: pumpthermd of DIR in the namespace, with its bus; waits until it
# listens. Sets $daemon_pid and $bus_pid.
start() {
  local dir=$1 replay=${2:-}
  # Not through in_ns: a function run in the background is a subshell, and $! would be that
  # subshell's, whose TERM leaves the bus running. ip netns exec execs the bus itself.
  ip netns exec "$ns" python3 "$src/tests/daemon/can_bus.py" "$dir/can" can0 \
    --record "$dir/out.txt" ${replay:+--replay "$replay"} >"$dir/bus.txt" 2>&1 &
  bus_pid=$!
  pids+=("$bus_pid")
  # Under the sanitizers (CI's ASan build) the shim is preloaded ahead of their runtime.
  ip netns exec "$ns" env LD_PRELOAD="$shim" CANSHIM_DIR="$dir/can" \
    ASAN_OPTIONS="${ASAN_OPTIONS:-}:verify_asan_link_order=0" "$daemon" --config "$dir/d.toml" \
    >"$dir/stdout.txt" 2>>"$dir/stderr.txt" &
  daemon_pid=$!
  pids+=("$daemon_pid")
  for _ in $(seq 100); do
    grep -q "listening on" "$dir/stderr.txt" 2>/dev/null && return 0
    kill -0 "$daemon_pid" 2>/dev/null || break
    sleep 0.1
  done
  failed "pumpthermd of $dir did not start: $(tail -3 "$dir/stderr.txt")"
  return 1
}
stop() {
  kill -TERM "$daemon_pid" 2>/dev/null
  wait "$daemon_pid" 2>/dev/null
  kill -TERM "$bus_pid" 2>/dev/null
  wait "$bus_pid" 2>/dev/null
}
# clear DIR [ARGS...]: pumptherm clear-trip pump1 as alice, inside the namespace.
clear_trip() {
  local dir=$1
  shift
  in_ns "$pumptherm" clear-trip pump1 -c "$dir/d.toml" --key "$tmp/alice.key" --timeout-s 3 "$@"
}
latched_in_safety() {  # DIR: the nodes latched for pump1 in the safety state
  python3 -c "import tomllib,sys; t=open(sys.argv[1]).read(); t=t[:t.rfind('# blake2b')]; \
print(' '.join(tomllib.loads(t)['pump']['pump1']['latched_trip_nodes']))" "$1/state/safety.toml"
}

case_clear() {
  say "clear: a signed clear over udpm, the answer signed by the gateway, the journal escaped"
  local d=$tmp/clear
  config "$d" hall1 HALL1
  latch "$d"
  start "$d" || return
  out=$(clear_trip "$d" --comment $'cooling restored\n<2>pumpthermd: forged line')
  rc=$?
  echo "$out"
  [ $rc -eq 0 ] || failed "clear-trip exit $rc"
  grep -q "pump1: the gateway accepted the clear (latched trip cleared); trip latched now: no" <<<"$out" ||
    failed "clear-trip did not report the accepted clear"
  stop
  grep -q "alarm clear from alice (key [0-9a-f]*) (counter [0-9]*) accepted (latched trip cleared): cooling restored\\\\n<2>pumpthermd: forged line" "$d/stderr.txt" ||
    failed "the accepted clear's journal line (escaped) is missing: $(grep 'alarm clear' "$d/stderr.txt")"
  grep -q '^<2>\|^pumpthermd: forged' "$d/stderr.txt" && failed "a forged journal line got through"
  [ -z "$(latched_in_safety "$d")" ] || failed "safety.toml still has pump1 latched"
  grep -q "clears 1 accepted, 0 refused" "$d/stdout.txt" || failed "the exit summary lacks the clear counters: $(head -1 "$d/stdout.txt")"
}

case_kill9() {
  say "kill9: kill -9 right after the client saw ACCEPTED, then the recorded clear replayed (6 runs)"
  local d=$tmp/kill9 replayed=0 run
  config "$d" hall1 HALL1
  for run in 1 2 3 4 5 6; do
    rm -f "$d/state/"*
    latch "$d"
    start "$d" || return
    in_ns "$tool" capture "$url" HALL1/pump1/ALARM_CLEAR "$d/cmd.bin" 5 >/dev/null &
    local cap=$!
    sleep 0.2
    out=$(clear_trip "$d") || failed "run $run: clear-trip: $out"
    kill -9 "$daemon_pid"
    wait "$daemon_pid" 2>/dev/null
    wait "$cap" || failed "run $run: the command was not captured"
    kill -TERM "$bus_pid"; wait "$bus_pid" 2>/dev/null
    : >"$d/stderr.txt"
    start "$d" || return
    in_ns "$tool" publish "$url" HALL1/pump1/ALARM_CLEAR "$d/cmd.bin" || failed "replay not sent"
    sleep 0.5
    stop
    grep -q "restored the safety state from .*: 0 latched trip(s)" "$d/stderr.txt" ||
      failed "run $run: the clear was not durable: $(grep -i 'safety' "$d/stderr.txt")"
    if grep -q ") accepted (" "$d/stderr.txt"; then replayed=$((replayed + 1)); fi
    grep -q "refused: counter .* is not above the last accepted" "$d/stderr.txt" ||
      failed "run $run: no refusal of the replay logged"
  done
  echo "replays accepted after kill -9: $replayed of 6"
  [ "$replayed" -eq 0 ] || failed "$replayed replays accepted"

  say "kill9: killed while the safety state is being written (paused 2 s): the clear did not act"
  rm -f "$d/state/"*
  latch "$d"
  sed -i 's/^status_period_s = 0.5$/status_period_s = 0.5\ntest_safety_write_pause_s = 2.0/' "$d/d.toml"
  : >"$d/stderr.txt"
  start "$d" || return
  clear_trip "$d" --timeout-s 1 >"$d/client.txt" 2>&1 &
  local client=$!
  sleep 0.7
  kill -9 "$daemon_pid"
  wait "$daemon_pid" 2>/dev/null
  wait "$client" && failed "the client saw an answer from a gateway killed before the clear was durable"
  kill -TERM "$bus_pid"; wait "$bus_pid" 2>/dev/null
  sed -i '/^test_safety_write_pause_s/d' "$d/d.toml"
  : >"$d/stderr.txt"
  start "$d" || return
  stop
  grep -q "removed .*safety.toml.tmp, an unfinished safety state write" "$d/stderr.txt" ||
    failed "the unfinished write was not found: $(grep -i safety "$d/stderr.txt")"
  [ "$(latched_in_safety "$d")" = winding ] || failed "the trip was cleared though its clear never became durable"
}

case_cross() {
  say "cross: a clear captured for gateway hall1 replayed onto hall2 (same operator key, same pump name)"
  local a=$tmp/crossA b=$tmp/crossB
  config "$a" hall1 HALL1
  config "$b" hall2 HALL2
  latch "$a"
  latch "$b"
  start "$a" || return
  local pa=$daemon_pid ba=$bus_pid
  start "$b" || return
  in_ns "$tool" capture "$url" HALL1/pump1/ALARM_CLEAR "$tmp/cross.bin" 5 >/dev/null &
  local cap=$!
  sleep 0.2
  clear_trip "$a" >/dev/null || failed "the clear on hall1 failed"
  wait "$cap" || failed "not captured"
  in_ns "$tool" publish "$url" HALL2/pump1/ALARM_CLEAR "$tmp/cross.bin" || failed "replay not sent"
  sleep 0.5
  stop
  daemon_pid=$pa bus_pid=$ba stop
  grep -q "refused: it is for gateway 'hall1', not this one ('hall2')" "$b/stderr.txt" ||
    failed "hall2 did not refuse hall1's clear: $(grep 'alarm clear' "$b/stderr.txt")"
  [ "$(latched_in_safety "$b")" = winding ] || failed "hall2's trip was cleared by hall1's command"
  [ -z "$(latched_in_safety "$a")" ] || failed "hall1's own clear did not act"
}

case_lan() {
  say "lan: a signed clear sent with ttl=1 from a second namespace over a veth"
  if ! ip netns add "$nsb" 2>/dev/null || ! ip link add ptva$$ type veth peer name ptvb$$ 2>/dev/null; then
    echo "SKIP lan: no veth here"; return
  fi
  ip link set ptva$$ netns "$ns"
  ip link set ptvb$$ netns "$nsb"
  ip -n "$ns" addr add 10.77.0.1/24 dev ptva$$
  ip -n "$nsb" addr add 10.77.0.2/24 dev ptvb$$
  ip -n "$ns" link set ptva$$ up
  ip -n "$nsb" link set ptvb$$ up
  ip -n "$nsb" link set lo up
  # The group is routed over the veth, as over a LAN interface: the daemon joins it there.
  ip -n "$ns" route replace 224.0.0.0/4 dev ptva$$
  ip -n "$nsb" route add 224.0.0.0/4 dev ptvb$$
  local d=$tmp/lan remote=(ip netns exec "$nsb" "$pumptherm" clear-trip pump1 -c "$tmp/none.toml"
    --url 'udpm://239.255.76.67:7667?ttl=1' --gateway hall1 --gateway-key "$tmp/hall1.key.pub"
    --prefix HALL1 --key "$tmp/alice.key" --timeout-s 1.5)
  LCM_URL='udpm://239.255.76.67:7667?ttl=1' config "$d" hall1 HALL1
  latch "$d"
  start "$d" || return
  grep -q "LCM receives from this host only" "$d/stderr.txt" || failed "no boundary line at start"
  "${remote[@]}" && failed "a clear from the second namespace was answered"
  # The host itself still reaches the daemon (its own multicast looped back over the veth).
  clear_trip "$d" >/dev/null || failed "the host's own clear was not answered"
  stop
  grep -q "alarm clear from alice .* accepted" "$d/stderr.txt" ||
    failed "the host's own clear did not reach the daemon: $(grep 'alarm clear' "$d/stderr.txt")"
  [ "$(grep -c "alarm clear" "$d/stderr.txt")" -eq 1 ] || failed "the remote clear reached the daemon"
  grep -q "lcm [1-9][0-9]* received dropped" "$d/stdout.txt" ||
    failed "the kernel's drops are not in the exit summary: $(head -1 "$d/stdout.txt")"
  echo "exit summary: $(grep -o 'lcm [0-9]* received dropped[^;]*' "$d/stdout.txt")"
  # Listed, the interface is taken: the same command now clears (the filter is what refused it).
  latch "$d"
  LCM_URL='udpm://239.255.76.67:7667?ttl=1' config "$d" hall1 HALL1 "receive_interfaces = [\"ptva$$\"]"
  : >"$d/stderr.txt"
  start "$d" || return
  "${remote[@]}" || failed "with lcm.receive_interfaces the remote clear was not taken"
  stop
}

case_lost() {
  say "lost: safety.toml deleted, then damaged: every pump latched, a recorded clear refused"
  local d=$tmp/lost
  config "$d" hall1 HALL1
  latch "$d"
  start "$d" || return
  in_ns "$tool" capture "$url" HALL1/pump1/ALARM_CLEAR "$d/cmd.bin" 5 >/dev/null &
  local cap=$!
  sleep 0.2
  clear_trip "$d" >/dev/null || failed "the first clear failed"
  wait "$cap"
  stop  # writes state.toml and safety.toml
  rm "$d/state/safety.toml"
  : >"$d/stderr.txt"
  start "$d" || return
  for p in pump1 pump2 pump3; do
    grep -q "pump $p: latched trip 'safety state lost': .*safety.toml is missing, while .*state.toml is there" "$d/stderr.txt" ||
      failed "$p did not latch 'safety state lost'"
  done
  in_ns "$tool" publish "$url" HALL1/pump1/ALARM_CLEAR "$d/cmd.bin"
  sleep 0.5
  grep -q "refused: signed before the gateway lost its clear counters" "$d/stderr.txt" ||
    failed "the recorded clear was not refused after the loss: $(grep 'alarm clear' "$d/stderr.txt")"
  clear_trip "$d" --node safety_state_lost >/dev/null || failed "a fresh clear of the state-lost latch failed"
  stop
  [ "$(latched_in_safety "$d")" = "" ] || failed "pump1 still latched: $(latched_in_safety "$d")"
  # One byte changed: found by the checksum, kept aside, latched again.
  sed -i 's/latched_trip_nodes/latched_trip_nodez/' "$d/state/safety.toml"
  : >"$d/stderr.txt"
  start "$d" || return
  stop
  grep -q "safety.toml is damaged: the checksum does not match its contents (damaged) (kept as .*safety.toml.damaged)" "$d/stderr.txt" ||
    failed "damage not reported: $(grep -i 'safety' "$d/stderr.txt" | head -3)"
  [ "$(latched_in_safety "$d")" = safety_state_lost ] || failed "after damage pump1 is not latched"
}

case_flood() {
  say "flood: 20 000 forged clears per second for 10 s, a legitimate clear inside"
  local d=$tmp/flood log=$build/tests/vcan/pipeline/pipeline.log now='import time; print(time.monotonic())'
  [ -s "$log" ] || { failed "no recording $log (build vcan_pipeline_recording)"; return; }
  config "$d" hall1 HALL1
  latch "$d"
  start "$d" "$log" || return
  sleep 5  # every pump heard, estimating, its outputs on their periods
  local b0 t0 t1
  b0=$(python3 -c "$now")
  sleep 10  # the same 10 s without a flood, to compare
  t0=$(python3 -c "$now")
  local cpu0 cpu1
  cpu0=$(awk '{print $14 + $15}' "/proc/$daemon_pid/stat")
  # Three sources: alice's key ID (a forged tag), a key not listed, a made-up ID.
  in_ns "$tool" flood "$url" HALL1 pump1 hall1 20000 10 "$alice_id" "$mallory_id" forged-source \
    >"$d/flood.txt" &
  local flood=$!
  sleep 5
  clear_trip "$d" --comment "inside the flood" >"$d/client.txt" 2>&1 ||
    failed "the legitimate clear inside the flood: $(cat "$d/client.txt")"
  wait "$flood" || failed "the flood tool failed"
  t1=$(python3 -c "$now")
  cpu1=$(awk '{print $14 + $15}' "/proc/$daemon_pid/stat")
  cat "$d/flood.txt" "$d/client.txt"
  python3 -c "import os,sys; print(f'pumpthermd used {(int(sys.argv[2]) - int(sys.argv[1])) / os.sysconf(\"SC_CLK_TCK\") / (float(sys.argv[4]) - float(sys.argv[3])) * 100:.0f} % of a core during the flood')" "$cpu0" "$cpu1" "$t0" "$t1"
  sleep 1
  stop
  head -1 "$d/stdout.txt"
  python3 - "$d/out.txt" "$b0" "$t0" "$t1" <<'PY' || fail=1
import collections, sys
path, b0, t0, t1 = sys.argv[1], *map(float, sys.argv[2:])
# Output messages of pump1..3 (DBC ID + node) and their cycles, s.
cycles = {0x200: 0.1, 0x400: 1.0, 0x410: 1.0, 0x420: 0.1, 0x430: 1.0, 0x600: 1.0}
times = collections.defaultdict(list)
for line in open(path):
    t, ident, *_ = line.split()
    times[int(ident, 16)].append(float(t))
def worst(ident, start, end, cycle):
    """Frames in [start, end] and the longest gap to a frame from its periodic predecessor. A
    GW_ALARM sent at once on a change (less than 0.8 cycles after the one before) takes the next
    periodic slot's place: the gap after it is counted from the periodic frame before it."""
    ts = [t for t in times[ident] if start <= t <= end]
    longest, prev = 0.0, None
    for a, b in zip(ts, ts[1:]):
        if b - a < 0.8 * cycle and prev is None:
            prev = a  # b came early, on a change: the next gap runs from a
            continue
        longest = max(longest, b - (prev if prev is not None else a) - (cycle if prev is not None else 0.0))
        prev = None
    return len(ts), longest if len(ts) > 1 else float('inf')
late = 0
for base, cycle in sorted(cycles.items()):
    for node in (1, 2, 3):
        n0, quiet = worst(base + node, b0, t0, cycle)
        n1, flood = worst(base + node, t0, t1, cycle)
        bad = flood > cycle + 0.05
        late += bad
        print(f"ID {base + node:X} (cycle {cycle * 1e3:.0f} ms): longest gap {quiet * 1e3:.1f} ms "
              f"without the flood ({n0} frames), {flood * 1e3:.1f} ms in it ({n1}){' LATE' if bad else ''}")
sys.exit(1 if late else 0)
PY
  local summaries
  summaries=$(grep -c "refused alarm clear(s) from .* not logged" "$d/stderr.txt")
  grep "refused alarm clear(s) from .* not logged" "$d/stderr.txt"
  [ "$summaries" -eq 3 ] || failed "$summaries summary lines, want one per source (3)"
  [ "$(grep -c 'alarm clear from .* refused' "$d/stderr.txt")" -le 5 ] || failed "more than 5 refusal lines"
  grep -q "accepted the clear" "$d/client.txt" || failed "no accepted answer inside the flood"
}

case_readers() {
  say "readers: pumptherm watch --gateway-key marks a phantom pump published by a forger"
  local d=$tmp/readers log=$build/tests/vcan/pipeline/pipeline.log
  [ -s "$log" ] || { failed "no recording $log (build vcan_pipeline_recording)"; return; }
  config "$d" hall1 HALL1
  start "$d" "$log" || return
  # The forger: pumptherm-lcm-demo publishing TEMPS and ALARM of a pump the gateway has not.
  in_ns "$build/tools/pumptherm-lcm-demo" --lcm-url "$url" --prefix HALL1 --pumps phantom \
    --duration-s 10 >/dev/null 2>&1 &
  local forger=$!
  local out
  out=$(in_ns "$pumptherm" watch --url "$url" --prefix HALL1 --gateway-key "$tmp/hall1.key.pub" \
    --period-s 0.35 --count 28)
  wait "$forger"
  stop
  echo "$out" | tail -n 8
  # A table printed between a message and the digest that lists it shows the message pending.
  # The gateway publishes its digest right after the pumps publish (at most ten per period), so
  # that window is short: pump1 must show as signed in most of 28 tables 0.35 s apart (a phase
  # that walks through the period). With a digest once per period on a timer of its own, pump1's
  # TEMPS could follow it closely in every period and stay pending almost all the time.
  local signed pending
  signed=$(echo "$out" | grep -c "^pump1 .*  signed$" || true)
  pending=$(echo "$out" | grep -c "^pump1 .*signature pending" || true)
  echo "readers: pump1 signed in $signed tables, pending in $pending"
  [ "$signed" -ge 14 ] || failed "pump1 is shown as signed in $signed of 28 tables (pending in $pending)"
  echo "$out" | tail -n 8 | grep -q "^phantom .*NOT FROM THE GATEWAY" || failed "the phantom pump is not marked"
}

for c in "${cases[@]}"; do
  "case_$c"
done
[ "$fail" -eq 0 ] && echo "PASS: ${cases[*]}"
exit "$fail"
