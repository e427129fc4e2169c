#!/usr/bin/env bash
# Alarm transitions in flight when the broker dies (docs/mqtt.md, "Beside the loop"): Debian's
# mosquitto on a free loopback port (plain text), `pumpthermd -r` paced
# (--pace 150) over the demo's first 1100 s (pump3 warns at 827 s, its forecast joins at 858 s,
# it trips at 990 s). Once the warning has reached the subscriber the broker is frozen
# (SIGSTOP): the daemon's connection stays up, so the next transitions are written into it and
# wait for a PUBACK that does not come. Once the daemon has logged the trip, the broker is
# killed (SIGKILL: what it had not read is gone) and a new one started on the same port. The
# daemon must send the unacknowledged transitions again after its new births: the summary's
# "alarms sent again" is at least 1, and the subscriber (which reconnects and asks for a
# rebirth) sees every alarm transition of the CSV (check_restart.py). Data steps written into
# the frozen connection are lost without being counted (QoS 0): not checked here.
#
#   alarm_inflight_test.sh PUMPTHERM PUMPTHERMD SOURCE_DIR
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

tmp=$(mktemp -d)
pids=()
cleanup() {
  for p in "${pids[@]}"; do kill -CONT "$p" 2>/dev/null || true; kill "$p" 2>/dev/null || true; done
  wait 2>/dev/null || true
  rm -rf "$tmp"
}
trap cleanup EXIT
cd "$tmp"

port=$($py -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
# Persistence saved every second: the subscriber's persistent session (its QoS 1 subscription)
# is on disk before the daemon starts, so the new broker queues the re-sent transitions for it
# even when the daemon reconnects first.
cat >mosquitto.conf <<EOF
user $(id -un)
log_dest file $tmp/mosquitto.log
listener $port 127.0.0.1
allow_anonymous true
persistence true
persistence_location $tmp/
autosave_interval 1
EOF
start_broker() {
  mosquitto -c mosquitto.conf &
  broker=$!
  pids+=($broker)
  for _ in $(seq 100); do
    $py -c "import socket; socket.create_connection(('127.0.0.1', $port), 0.2)" 2>/dev/null && return 0
    sleep 0.1
  done
  echo "FAIL: the broker did not listen"; exit 1
}
start_broker
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
queue_steps = 32
EOF
} >"$tmp/gw.toml"

# The subscriber freezes the daemon (SIGSTOP) when pump3's warning reaches it, so that the broker
# is frozen before the next transitions however slowly this machine runs.
$py -u "$here/subscriber.py" --port "$port" --edge-node gw1 --out "$tmp/sub.jsonl" --timeout 60 \
  --persistent --stop-file "$tmp/done" --pause-device pump3 --pause-pid-file "$tmp/daemon.pid" \
  --paused-file "$tmp/paused" >"$tmp/sub.stdout" 2>&1 &
sub=$!
pids+=($sub)
for _ in $(seq 100); do grep -q subscribed "$tmp/sub.stdout" 2>/dev/null && break; sleep 0.1; done
grep -q subscribed "$tmp/sub.stdout" || { echo "FAIL: the subscriber did not subscribe"; exit 1; }
sleep 1.5  # the broker's autosave: the subscriber's session on disk

TZ=UTC "$pumpthermd" --config "$tmp/gw.toml" -r "$tmp/short.log" --csv-dir "$tmp/est" \
  --pace 150 >"$tmp/out.txt" 2>"$tmp/err.txt" &
d=$!
pids+=($d)
echo "$d" >"$tmp/daemon.pid"
for _ in $(seq 1000); do [[ -e $tmp/paused ]] && break; sleep 0.02; done
[[ -e $tmp/paused ]] || { echo "FAIL: pump3's warning did not arrive"; cat "$tmp/err.txt"; exit 1; }
kill -STOP "$broker"
kill -CONT "$d"
echo "broker frozen"
for _ in $(seq 300); do grep -q "pump3: trip:" "$tmp/err.txt" && break; sleep 0.02; done
grep -q "pump3: trip:" "$tmp/err.txt" || { echo "FAIL: no trip while the broker was frozen"; exit 1; }
sleep 0.3  # the trip's step reaches the sink's thread and is written into the frozen connection
kill -KILL "$broker"
wait "$broker" 2>/dev/null || true
start_broker
echo "broker killed and started again"
wait "$d" || { echo "FAIL: pumpthermd"; cat "$tmp/err.txt"; exit 1; }
touch "$tmp/done"
wait "$sub" || { echo "FAIL: subscriber"; cat "$tmp/out.txt" "$tmp/err.txt"; exit 1; }
grep '^mqtt' "$tmp/out.txt"
resent=$(sed -n 's/^mqtt .*, \([0-9]*\) alarms sent again$/\1/p' "$tmp/out.txt")
((resent >= 1)) || { echo "FAIL: no alarm transition was in flight: the test proves nothing"; exit 1; }
grep -qE '^mqtt .*, 0 alarms dropped' "$tmp/out.txt" || { echo "FAIL: alarms dropped"; exit 1; }
dropped=$(sed -n 's/^mqtt .*, \([0-9]*\) dropped, .*/\1/p' "$tmp/out.txt")
$py "$here/check_restart.py" --messages "$tmp/sub.jsonl" --csv-dir "$tmp/est" \
  --group plant --edge-node gw1 --pumps pump1 pump2 pump3 --origin-s "$first" \
  --dropped "$dropped" --max-lost 100000 --no-restart
echo PASS
