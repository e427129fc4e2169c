#!/usr/bin/env bash
# The MQTT sink against a real broker (docs/mqtt.md, "Tested"): Debian's mosquitto on a free
# loopback port with TLS (a CA, server and client certificates made here with openssl, client
# certificates required), `pumpthermd -r` on the first 1100 s of the demo recording (pump3
# warns at 839 s and trips at 989 s) with [mqtt] on, and an independent subscriber (python3-paho-mqtt, the schema compiled here by
# protoc) whose messages are checked against the daemon's own CSV (check_messages.py). Then
# the daemon is killed (SIGKILL) during a paced run: the broker must send its NDEATH (the will).
# Then the broker is stopped and restarted during a paced run (check_restart.py): every alarm
# transition arrives, the data steps lost meanwhile are counted.
#
#   broker_test.sh PUMPTHERM PUMPTHERMD SOURCE_DIR
set -euo pipefail
pumptherm=$1
pumpthermd=$2
src=$3
here=$(cd "$(dirname "$0")" && pwd)
# Debian's python3 (python3-paho-mqtt, python3-protobuf), not another one earlier on PATH.
py=/usr/bin/python3
[[ -x $py ]] || py=python3
for tool in mosquitto openssl protoc; do
  command -v "$tool" >/dev/null || { echo "SKIP: $tool not installed (tools/setup.sh)"; exit 77; }
done
$py -c 'import paho.mqtt.client, google.protobuf' 2>/dev/null ||
  { echo "SKIP: python3-paho-mqtt or python3-protobuf not installed (tools/setup.sh)"; exit 77; }

tmp=$(mktemp -d)
chmod 700 "$tmp"
pids=()
cleanup() {
  for p in "${pids[@]}"; do kill -CONT "$p" 2>/dev/null || true; kill "$p" 2>/dev/null || true; done
  wait 2>/dev/null || true
  rm -rf "$tmp"
}
trap cleanup EXIT
[[ -n ${MQTT_TEST_KEEP:-} ]] && trap - EXIT && echo "keeping $tmp"

# --- the test CA, the broker's and the gateway's certificates ---
cd "$tmp"
ossl() { openssl "$@" >/dev/null 2>&1; }
ossl req -x509 -newkey rsa:2048 -nodes -keyout ca.key -out ca.pem -days 2 -subj "/CN=pumptherm test CA"
for who in server client; do
  ossl req -newkey rsa:2048 -nodes -keyout "$who.key" -out "$who.csr" -subj "/CN=$who"
  printf 'subjectAltName=IP:127.0.0.1,DNS:localhost\n' >"$who.ext"
  ossl x509 -req -in "$who.csr" -CA ca.pem -CAkey ca.key -CAcreateserial -out "$who.pem" -days 2 \
    -extfile "$who.ext"
done
chmod 600 ./*.key

# --- the broker: TLS only, client certificates required, on a free loopback port ---
port=$($py -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
cat >mosquitto.conf <<EOF
persistence true
persistence_location $tmp/
user $(id -un)
log_dest file $tmp/mosquitto.log
listener $port 127.0.0.1
cafile $tmp/ca.pem
certfile $tmp/server.pem
keyfile $tmp/server.key
require_certificate true
allow_anonymous true
EOF
start_broker() {
  mosquitto -c mosquitto.conf &
  broker=$!
  pids+=($broker)
  for _ in $(seq 100); do
    $py -c "import socket; socket.create_connection(('127.0.0.1', $port), 0.2)" 2>/dev/null && return 0
    sleep 0.1
  done
  echo "FAIL: the broker did not listen"; cat "$tmp/mosquitto.log"; exit 1
}
start_broker

# --- the schema for the subscriber, compiled here ---
protoc --python_out="$tmp" -I "$src/protocol" "$src/protocol/sparkplug_b.proto"

# --- the demo's first 1100 s (pump3 warns at 839 s, trips at 989 s), and the daemon's configuration with [mqtt] ---
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
ca_file = "$tmp/ca.pem"
cert_file = "$tmp/client.pem"
key_file = "$tmp/client.key"
EOF
} >"$tmp/gw.toml"

subscribe() {  # subscribe OUT DEATHS [OPTIONS]: starts the subscriber, returns once subscribed
  $py -u "$here/subscriber.py" --port "$port" --ca ca.pem --cert client.pem --key client.key \
    --edge-node gw1 --deaths "$2" --out "$1" --timeout 120 "${@:3}" >"$1.stdout" &
  sub=$!
  pids+=($sub)
  for _ in $(seq 100); do grep -q subscribed "$1.stdout" 2>/dev/null && return 0; sleep 0.1; done
  echo "FAIL: the subscriber did not subscribe"; cat "$tmp/mosquitto.log"; exit 1
}

# --- 1. a whole run: births, every step against the CSV, the NDEATH of a clean end ---
export PYTHONPATH="$tmp"
subscribe "$tmp/run.jsonl" 1
start=$(date +%s.%N)
TZ=UTC "$pumpthermd" --config "$tmp/gw.toml" -r "$tmp/short.log" --csv-dir "$tmp/est" \
  >"$tmp/out.txt" 2>"$tmp/err.txt" || { echo "FAIL: pumpthermd"; cat "$tmp/err.txt"; exit 1; }
wait "$sub" || { echo "FAIL: subscriber"; cat "$tmp/err.txt"; exit 1; }
grep '^mqtt' "$tmp/out.txt"
# pump3's warning and trip went as alarm transitions (QoS 1).
grep -qE '^mqtt .*, [1-9][0-9]* alarms sent, 0 dropped, 0 alarms dropped' "$tmp/out.txt" ||
  { echo "FAIL: no alarm transition sent, or steps dropped"; exit 1; }
echo "run: $($py -c "import time; print(f'{time.time() - $start:.1f}')") s"
$py "$here/check_messages.py" --messages "$tmp/run.jsonl" --csv-dir "$tmp/est" --group plant \
  --edge-node gw1 --pumps pump1 pump2 pump3 --origin-s "$first"

# --- 2. killed: the broker sends the will, the NDEATH of the session's bdSeq ---
subscribe "$tmp/kill.jsonl" 1
TZ=UTC "$pumpthermd" --config "$tmp/gw.toml" -r "$tmp/short.log" --pace 20 \
  >/dev/null 2>"$tmp/err-kill.txt" &
d=$!
for _ in $(seq 100); do grep -q DDATA "$tmp/kill.jsonl" 2>/dev/null && break; sleep 0.1; done
kill -KILL "$d"
wait "$d" 2>/dev/null || true
wait "$sub" || { echo "FAIL: no NDEATH after SIGKILL"; exit 1; }
$py - "$tmp/kill.jsonl" <<'EOF'
import json, sys
msgs = [json.loads(l) for l in open(sys.argv[1])]
births = [m for m in msgs if m["topic"] == "spBv1.0/plant/NBIRTH/gw1"]
deaths = [m for m in msgs if m["topic"] == "spBv1.0/plant/NDEATH/gw1"]
bd = lambda m: [x["value"] for x in m["metrics"] if x["name"] == "bdSeq"][0]
assert births and deaths, (len(births), len(deaths))
assert bd(deaths[-1]) == bd(births[-1]), (bd(deaths[-1]), bd(births[-1]))
data = sum(1 for m in msgs if "/DDATA/" in m["topic"])
print(f"killed: NDEATH bdSeq {bd(deaths[-1])} = the NBIRTH's, after {data} DDATA")
EOF

# --- 3. the broker stopped and restarted mid-run: no alarm transition lost, drops counted ---
# The whole demo (1200 s), paced at 150 log s per s, so that a full data queue drops as live
# (docs/mqtt.md). The broker
# stops once pump3's warning (833 s) has arrived and comes back once the daemon has logged the
# trip (979 s): the forecast's transition (857 s) and the trip fall in the outage, kept in the
# alarm queue and sent after the next births. The subscriber keeps a persistent session (QoS 1)
# that the broker's persistence carries across its restart, and asks for a rebirth when it
# is back (the gateway may have reconnected first: births are QoS 0).
{
  cat "$tmp/gw.toml"
  echo "queue_steps = 32"
} >"$tmp/gw-restart.toml"
start3=$(date +%s.%N)
# The subscriber freezes the daemon (SIGSTOP) when pump3's warning reaches it, so the broker
# stops between the warning and the trip however slowly this machine runs.
subscribe "$tmp/restart.jsonl" 1 --persistent --stop-file "$tmp/restart.done" \
  --pause-device pump3 --pause-pid-file "$tmp/restart.pid" --paused-file "$tmp/restart.paused"
TZ=UTC "$pumpthermd" --config "$tmp/gw-restart.toml" -r "$tmp/demo/demo.log" --csv-dir "$tmp/est-restart" \
  --pace 150 >"$tmp/out-restart.txt" 2>"$tmp/err-restart.txt" &
d=$!
pids+=($d)
echo "$d" >"$tmp/restart.pid"
for _ in $(seq 1500); do [[ -e $tmp/restart.paused ]] && break; sleep 0.02; done
[[ -e $tmp/restart.paused ]] || { echo "FAIL: pump3's warning did not arrive"; cat "$tmp/err-restart.txt"; exit 1; }
grep -q "pump3: trip:" "$tmp/err-restart.txt" && { echo "FAIL: the trip came before the broker stopped"; exit 1; }
kill -TERM "$broker"
wait "$broker" 2>/dev/null || true
kill -CONT "$d"
echo "broker stopped"
for _ in $(seq 300); do grep -q "pump3: trip:" "$tmp/err-restart.txt" && break; sleep 0.02; done
start_broker
echo "broker restarted"
wait "$d" || { echo "FAIL: pumpthermd"; cat "$tmp/err-restart.txt"; exit 1; }
touch "$tmp/restart.done"
wait "$sub" || {
  echo "FAIL: subscriber"; cat "$tmp/out-restart.txt" "$tmp/err-restart.txt"
  cut -c1-90 "$tmp/restart.jsonl" | grep -v DDATA; tail -n 20 "$tmp/mosquitto.log"; exit 1
}
grep '^mqtt' "$tmp/out-restart.txt"
dropped=$(sed -n 's/^mqtt .*, \([0-9]*\) dropped, .*/\1/p' "$tmp/out-restart.txt")
grep -qE '^mqtt .*, 0 alarms dropped' "$tmp/out-restart.txt" || { echo "FAIL: alarms dropped"; exit 1; }
$py "$here/check_restart.py" --messages "$tmp/restart.jsonl" --csv-dir "$tmp/est-restart" \
  --group plant --edge-node gw1 --pumps pump1 pump2 pump3 --origin-s "$first" \
  --dropped "$dropped" --max-lost 128
echo "restart part: $($py -c "import time; print(f'{time.time() - $start3:.1f}')") s"
echo PASS
