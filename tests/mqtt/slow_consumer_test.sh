#!/usr/bin/env bash
# A slow consumer on the broker (docs/mqtt.md, "Tested"): Debian's mosquitto on a free loopback
# port (plain text: the sink allows it to this host) with a per-client queue limit
# (max_inflight_messages, max_queued_messages), and `pumpthermd -r` paced (--pace) over the demo's
# first 1100 s (pump3 warns at 827 s, trips at 990 s), twice: (A) with one normal subscriber, (B) with the same
# subscriber and a second one that reads slowly (it sleeps after each message, its socket's
# receive buffer small). Checks:
# - the broker dropped messages for the slow client (its log says so), and that client got
#   fewer messages than the normal one (else the test proves nothing);
# - run B took no longer than run A (wall time, at most 50 % + 2 s more: a loaded machine moves a
#   paced run by a second or more, and a daemon held back by the slow client would take minutes),
#   and the daemon dropped no more steps in B than in A (+64): its loop and its sink are not held
#   back;
# - the normal subscriber of run B saw every alarm transition, each metric equal to the CSV,
#   and every step the daemon did not count as dropped (check_restart.py --no-restart).
#
#   slow_consumer_test.sh PUMPTHERM PUMPTHERMD SOURCE_DIR
set -euo pipefail
pumptherm=$1
pumpthermd=$2
src=$3
here=$(cd "$(dirname "$0")" && pwd)
py=/usr/bin/python3
[[ -x $py ]] || py=python3
for tool in mosquitto protoc; do
  command -v "$tool" >/dev/null || { echo "SKIP: $tool not installed (tools/setup.sh)"; exit 77; }
done
$py -c 'import paho.mqtt.client, google.protobuf' 2>/dev/null ||
  { echo "SKIP: python3-paho-mqtt or python3-protobuf not installed (tools/setup.sh)"; exit 77; }

pace=${MQTT_SLOW_PACE:-200}
tmp=$(mktemp -d)
pids=()
cleanup() {
  for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done
  wait 2>/dev/null || true
  rm -rf "$tmp"
}
trap cleanup EXIT
[[ -n ${MQTT_TEST_KEEP:-} ]] && trap - EXIT && echo "keeping $tmp"
cd "$tmp"

port=$($py -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
# The per-client limits: at most 1 QoS 1 message in flight (not acknowledged) and 2 queued
# behind it. Mosquitto 2.0.11 counts only those against the limit: QoS 0 messages for an online
# client go to its outgoing buffer however far behind it is (without these limits the slow
# client here got 55 of 3000 messages and the broker held the rest in memory), and are dropped
# only once the client's QoS 1 queue is full. The slow client acknowledges the first alarm
# transition late, so from the third on its messages are dropped.
cat >mosquitto.conf <<EOF
user $(id -un)
log_dest file $tmp/mosquitto.log
listener $port 127.0.0.1
allow_anonymous true
max_inflight_messages 1
max_queued_messages 2
EOF
mosquitto -c mosquitto.conf &
pids+=($!)
for _ in $(seq 100); do
  $py -c "import socket; socket.create_connection(('127.0.0.1', $port), 0.2)" 2>/dev/null && break
  sleep 0.1
done
protoc --python_out="$tmp" -I "$src/protocol" "$src/protocol/sparkplug_b.proto"
export PYTHONPATH="$tmp"

"$pumptherm" plant demo --out "$tmp/demo" --quiet
first=$(head -n 1 "$tmp/demo/demo.log" | sed 's/^(\([0-9]*\)\..*/\1/')
awk -v end=$((first + 1100)) '{ t = substr($1, 2) + 0; if (t >= end) exit; print }' \
  "$tmp/demo/demo.log" >"$tmp/short.log"
{
  cat "$src/tools/demo/pumpthermd-demo.toml"
  cat <<EOF

[mqtt]
host = "127.0.0.1"
port = $port
group_id = "plant"
edge_node_id = "gw1"
EOF
} >"$tmp/gw.toml"

subscribe() {  # subscribe NAME [OPTIONS]: starts a subscriber, returns once subscribed
  $py -u "$here/subscriber.py" --port "$port" --edge-node gw1 --out "$tmp/$1.jsonl" \
    --client-id "$1" --timeout 60 "${@:2}" >"$tmp/$1.stdout" 2>&1 &
  pids+=($!)
  last=$!
  for _ in $(seq 100); do grep -q subscribed "$tmp/$1.stdout" 2>/dev/null && return 0; sleep 0.1; done
  echo "FAIL: subscriber $1 did not subscribe"; cat "$tmp/mosquitto.log"; exit 1
}

run() {  # run NAME: the paced daemon; prints its wall time in s
  local t0 t1
  t0=$(date +%s.%N)
  TZ=UTC "$pumpthermd" --config "$tmp/gw.toml" -r "$tmp/short.log" --pace "$pace" \
    --csv-dir "$tmp/est-$1" >"$tmp/out-$1.txt" 2>"$tmp/err-$1.txt" ||
    { echo "FAIL: pumpthermd ($1)" >&2; cat "$tmp/err-$1.txt" >&2; exit 1; }
  t1=$(date +%s.%N)
  $py -c "print(f'{$t1 - $t0:.2f}')"
}
dropped_of() { sed -n 's/^mqtt .*, \([0-9]*\) dropped, .*/\1/p' "$tmp/out-$1.txt"; }

# --- A: one normal subscriber ---
subscribe normal-a
normal_a=$last
wall_a=$(run a)
wait "$normal_a" || { echo "FAIL: the subscriber of run A saw no NDEATH"; exit 1; }
grep '^mqtt' "$tmp/out-a.txt"

# --- B: the normal subscriber and a slow one ---
subscribe slow --sleep-s 0.05 --rcvbuf 2048
slow=$last
subscribe normal-b
normal_b=$last
wall_b=$(run b)
wait "$normal_b" || { echo "FAIL: the normal subscriber of run B saw no NDEATH"; exit 1; }
kill "$slow" 2>/dev/null || true
grep '^mqtt' "$tmp/out-b.txt"

n_normal=$(wc -l <"$tmp/normal-b.jsonl")
n_slow=$(wc -l <"$tmp/slow.jsonl")
d_a=$(dropped_of a)
d_b=$(dropped_of b)
echo "pace $pace: run A (normal subscriber) ${wall_a} s, dropped $d_a; run B (+ slow consumer)" \
  "${wall_b} s, dropped $d_b; messages: normal $n_normal, slow $n_slow"
grep -i "dropped" "$tmp/mosquitto.log" || true
grep -q "Outgoing messages are being dropped for client slow" "$tmp/mosquitto.log" ||
  { echo "FAIL: the broker dropped nothing for the slow client: the test proves nothing"; exit 1; }
((n_slow < n_normal)) || { echo "FAIL: the slow client got as many messages as the normal one"; exit 1; }
$py -c "import sys; a, b = $wall_a, $wall_b; sys.exit(0 if b <= a * 1.5 + 2.0 else 1)" ||
  { echo "FAIL: run B took ${wall_b} s against ${wall_a} s without the slow consumer"; exit 1; }
((d_b <= d_a + 64)) || { echo "FAIL: the daemon dropped $d_b steps with the slow consumer, $d_a without"; exit 1; }
grep -qE '^mqtt .*, 0 alarms dropped' "$tmp/out-b.txt" || { echo "FAIL: alarms dropped"; exit 1; }
$py "$here/check_restart.py" --messages "$tmp/normal-b.jsonl" --csv-dir "$tmp/est-b" \
  --group plant --edge-node gw1 --pumps pump1 pump2 pump3 --origin-s "$first" \
  --dropped "$d_b" --max-lost 0 --no-restart
echo PASS
