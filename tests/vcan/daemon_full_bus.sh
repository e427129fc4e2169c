#!/bin/sh
# Live load: vcan0 carries the frame rate of a fully loaded 1 Mbit/s bus (9000
# frames/s: 16 pumps of the plant's fleet32 recording, 3360 frames/s, plus filler frames the
# gateway does not know; tests/vcan/full_bus_log.awk) for 40 s, replayed by canplayer with its
# original timing, and the daemon (16 pumps) must take every frame off its socket: rx = frames on
# the bus, 0 receive-queue drops. Also checks that the bus really carried a full bus's rate (at
# least 7407 frames/s on average, an 8-byte frame with worst-case stuffing: 135 bit) and that the
# daemon logged the receive buffer it got.
# A measurement, not in CI (label "measurement"; docs/robustness.md, "Soak", has what the
# daemon's CPU costs in the QEMU TCG guest and offline on the host). In the guest it needs a deep
# queue: rx_buffer_bytes = 8 MiB here (with the default 1 MiB: 752 drops of
# 359,986). CTest gives the guest two CPUs (PUMPTHERM_VCAN_SMP=2): sharing one with the daemon,
# canplayer only just reached the full rate in 40 s (7038 and 7442 frames/s) and fell below it
# over 15 min (6716 and 6793); with two it keeps the recording's 9000. This is 40 s of traffic;
# the issue's 15 minutes are daemon_full_bus_15min.sh, which sets FULL_BUS_LOOPS and sources this
# file (canplayer -l: the recording played that many times).
# LATENCY=1 (daemon_full_bus_latency.sh) also records the bus with candump while canplayer plays
# it, for tests/bench/reaction_latency.py (docs/robustness.md, "Live reaction"), and the daemon's
# CPU share over the playback; the capture goes to $OUT_DIR/bus.log.gz.
set -eu
SCENARIO_NAME=${SCENARIO_NAME:-daemon_full_bus}
loops=${FULL_BUS_LOOPS:-1}
latency=${LATENCY:-0}
. "$DATA_DIR/daemon_lib.sh"

{
  printf '[gateway]\nname = "full-bus"\nheartbeat_period_s = 0\n\n'
  printf '[dbc]\nfile = "%s/pumptherm.dbc"\nmapping = "%s/mapping_pumptherm.toml"\n\n' "$DATA_DIR" "$DATA_DIR"
  # 8 MiB (about 16,000 frames): the emulated CPU falls behind for seconds at a time.
  printf '[[can]]\ninterface = "vcan0"\nrx_buffer_bytes = 8388608\n'
  for n in 0 1 2 3 4 5 6 7 8 9 10 11 12 13 14 15; do
    printf '\n[[pump]]\nname = "a%02d"\nnode_id = %d\nmotor = "han2019-tmp"\nthermal_model = "%s/tmp-generic.toml"\n' \
      "$n" "$n" "$DATA_DIR"
  done
} >"$WORK_DIR/pumpthermd.toml"
"$BIN_DIR/pumpthermd" --check-config "$WORK_DIR/pumpthermd.toml" >/dev/null || fail "the test configuration is invalid"

log=$DATA_DIR/full_bus.log
n_log=$(wc -l <"$log")
n_bus=$((n_log * loops))
span_s=$(tail -n 1 "$log" | awk '{ print substr($1, 2, length($1) - 2) + 0 }')
echo "$SCENARIO_NAME: $n_log frames over $span_s s ($(awk -v n="$n_log" -v s="$span_s" 'BEGIN { printf "%.0f", n / s }') frames/s in the log), played $loops time(s): $n_bus frames"

start_daemon "$WORK_DIR/pumpthermd.toml"
buffer=$(grep -o 'vcan0: receive buffer.*' "$WORK_DIR/daemon.err" | head -n 1)
echo "$SCENARIO_NAME: $buffer"
[ -n "$buffer" ] || fail "the daemon did not log its receive buffer"
# The daemon's CPU time so far (utime + stime, clock ticks of 10 ms).
cpu_ticks() { awk '{ print $14 + $15 }' "/proc/$DAEMON_PID/stat"; }
if [ "$latency" = 1 ]; then
  # Only the pumps' telemetry (0x100-0x11F, 0x180-0x18F) and the gateway's GW_ALARM (0x200-0x20F)
  # and GW_NODE_TEMP (0x480-0x48F), filtered in the kernel: the filler frames and the other
  # outputs would only cost the emulated CPUs. Kernel receive stamps (-L: candump's log format).
  candump -L -r 16777216 vcan0,100:7E0,180:7F0,200:7F0,480:7F0 >"$WORK_DIR/bus.log" &
  CANDUMP_PID=$!
  sleep 1
  kill -0 "$CANDUMP_PID" 2>/dev/null || fail "candump did not start"
fi
# /proc/uptime: 10 ms resolution (busybox date has no sub-second clock).
ticks0=$(cpu_ticks)
up0=$(cut -d' ' -f1 /proc/uptime)
canplayer -I "$log" -l "$loops" || fail "canplayer failed"
up1=$(cut -d' ' -f1 /proc/uptime)
ticks1=$(cpu_ticks)
sleep 1
if [ "$latency" = 1 ]; then
  kill -INT "$CANDUMP_PID"
  wait "$CANDUMP_PID" || true
  gzip -1 -c "$WORK_DIR/bus.log" >"$OUT_DIR/bus.log.gz"
  echo "$SCENARIO_NAME: candump recorded $(wc -l <"$WORK_DIR/bus.log") frames (pump telemetry, GW_ALARM, GW_NODE_TEMP)"
  share=$(awk -v a="$ticks0" -v b="$ticks1" -v u0="$up0" -v u1="$up1" 'BEGIN { printf "%.1f", (b - a) / (u1 - u0) }')
  echo "$SCENARIO_NAME: the daemon's CPU share during the playback: $share % of one CPU ($(((ticks1 - ticks0) / 100)).$(printf '%02d' $(((ticks1 - ticks0) % 100))) s over $(awk -v a="$up0" -v b="$up1" 'BEGIN { printf "%.2f", b - a }') s)"
  echo "cpu_share_percent=$share" >"$OUT_DIR/figures.txt"
fi
kill -0 "$DAEMON_PID" 2>/dev/null || fail "the daemon died"
# The daemon's CPU time (utime + stime, clock ticks of 10 ms): how close the emulated CPU came.
cpu=$(awk '{ printf "%.2f", ($14 + $15) / 100 }' "/proc/$DAEMON_PID/stat")
stop_daemon

status=$(head -n 1 "$WORK_DIR/daemon.out")
rx=$(echo "$status" | sed -n 's/^.*rx \([0-9]*\) frames.*$/\1/p')
rx_drops=$(echo "$status" | sed -n 's/^.*, \([0-9]*\) rx drops.*$/\1/p')
rate=$(awk -v n="$n_bus" -v a="$up0" -v b="$up1" 'BEGIN { printf "%.0f", n / (b - a) }')
echo "$SCENARIO_NAME: canplayer put $n_bus frames on vcan0 in $(awk -v a="$up0" -v b="$up1" 'BEGIN { printf "%.2f", b - a }') s: $rate frames/s on average"
echo "$SCENARIO_NAME: gateway: $status"
echo "$SCENARIO_NAME: the daemon used $cpu s of CPU (user + system) for the run"
if [ "$latency" = 1 ]; then
  printf 'frames_per_s=%s\nrx=%s\nrx_drops=%s\n' "$rate" "$rx" "$rx_drops" >>"$OUT_DIR/figures.txt"
fi
[ -n "$rx" ] && [ -n "$rx_drops" ] || fail "cannot read the daemon's counters"
[ "$rx_drops" -eq 0 ] || fail "$rx_drops receive-queue drops at $rate frames/s"
[ "$rx" -eq "$n_bus" ] || fail "the daemon received $rx of the $n_bus frames on the bus"
[ "$rate" -ge 7407 ] || fail "the bus carried $rate frames/s, less than a full 1 Mbit/s bus (7407 at least): canplayer fell behind"
echo "$SCENARIO_NAME: PASS ($n_bus frames at $rate frames/s, 0 drops)"
