#!/bin/sh
# vcan harness smoke scenario (POSIX sh: runs under busybox sh, dash and bash).
#
# 1. candump -L sees exactly the frames cansend put on vcan0 (standard, extended, RTR, empty,
#    8-byte, CAN FD), in order and unchanged.
# 2. `ip link set vcan0 down`: sending fails; iproute2's ip sets the MTU to 16 (classic CAN only);
#    `up`: the same candump (-D survives the interface going down) sees the frames sent
#    afterwards, and a CAN FD frame is refused.
# Each phase's frames go between a "sync" frame (7FF#5C<phase>) that proves candump is listening
# and an "end" frame (7FE#E0<phase>) that proves it has seen everything before it; the check is on
# what lies between.
set -eu

log=$WORK_DIR/candump.log
fail() {
  echo "smoke: FAIL: $*"
  if [ -f "$log" ]; then
    echo "smoke: candump saw:"
    sed 's/^/  /' "$log"
  fi
  exit 1
}

# Waits (up to about 10 s) until candump's log holds a line ending in " vcan0 $1"; while waiting,
# sends the frame $1 again every 0.2 s when $2 is "resend".
wait_for_frame() {
  tries=0
  until grep -q " vcan0 $1\$" "$log"; do
    tries=$((tries + 1))
    [ "$tries" -le 50 ] || fail "candump never showed $1"
    [ "${2:-}" = resend ] && cansend vcan0 "$1"
    sleep 0.2
  done
}

# Sends the frames in file $1 between a sync and an end frame and checks that candump saw exactly
# them. $2 names the phase in messages, $3 (two hex digits) marks its sync and end frames.
send_and_check() {
  sync=7FF#5C$3
  end=7FE#E0$3
  wait_for_frame "$sync" resend
  while read -r frame; do cansend vcan0 "$frame" || fail "$2: cansend vcan0 $frame failed"; done <"$1"
  cansend vcan0 "$end"
  wait_for_frame "$end"
  # The frames after the last sync frame and before the end frame, without timestamps.
  awk -v sync=" vcan0 $sync" -v end=" vcan0 $end" '
    index($0, sync) && substr($0, length($0) - length(sync) + 1) == sync { n = 0; on = 1; next }
    index($0, end) && substr($0, length($0) - length(end) + 1) == end { exit }
    on { sub(/^\([0-9.]+\) /, ""); seen[++n] = $0 }
    END { for (i = 1; i <= n; i++) print seen[i] }' "$log" >"$WORK_DIR/$2.seen"
  sed 's/^/vcan0 /' "$1" >"$WORK_DIR/$2.expected"
  if ! cmp -s "$WORK_DIR/$2.expected" "$WORK_DIR/$2.seen"; then
    echo "smoke: $2: expected:"
    sed 's/^/  /' "$WORK_DIR/$2.expected"
    echo "smoke: $2: seen between sync and end:"
    sed 's/^/  /' "$WORK_DIR/$2.seen"
    fail "$2: candump did not see exactly the frames sent"
  fi
  echo "smoke: $2: candump saw exactly the $(wc -l <"$1" | tr -d ' ') frames sent"
}

ip -details link show dev vcan0 | grep -q 'vcan' || fail "vcan0 is not a vcan device"
ip link show dev vcan0 | grep -q '[<,]UP[,>]' || fail "vcan0 is not up"
ip -details link show dev vcan0 | sed 's/^/smoke: /' 

candump -D -L vcan0 >"$log" 2>"$WORK_DIR/candump.err" &
candump_pid=$!
trap 'kill "$candump_pid" 2>/dev/null || true' EXIT

# The last frame is CAN FD (vcan0 starts with mtu 72) with flags 5 = CANFD_BRS | CANFD_FDF:
# kernels since 6.0 set FDF on every CAN FD frame they deliver and older ones pass the flags
# through, so candump prints 5 on both.
cat >"$WORK_DIR/classic.frames" <<'EOF'
123#DEADBEEF
000#
7FD#0102030405060708
1ABCDEF0#11223344
12345678#R
321#00
18FF50E5##5000102030405060708090A0B0C0D0E0F
EOF
send_and_check "$WORK_DIR/classic.frames" classic 01

ip link set dev vcan0 down
ip link show dev vcan0 | grep -q '[<,]UP[,>]' && fail "vcan0 still up after ip link set down"
if cansend vcan0 123#01 >/dev/null 2>&1; then fail "cansend succeeded while vcan0 was down"; fi
ip link set dev vcan0 mtu 16
ip link set dev vcan0 up
ip link show dev vcan0 | grep -q '[<,]UP[,>]' || fail "vcan0 not up after ip link set up"
ip link show dev vcan0 | grep -q ' mtu 16 ' || fail "vcan0 did not take mtu 16 (classic CAN)"
kill -0 "$candump_pid" 2>/dev/null || fail "candump -D exited when vcan0 went down"
if cansend vcan0 123##1AA >/dev/null 2>&1; then fail "a CAN FD frame was sent with mtu 16"; fi
echo "smoke: vcan0 went down (cansend refused) and up again with mtu 16 (CAN FD refused)"

cat >"$WORK_DIR/after-up.frames" <<'EOF'
456#CAFE
1FFFFFFF#0011223344556677
EOF
send_and_check "$WORK_DIR/after-up.frames" after-up 02

kill "$candump_pid"
wait "$candump_pid" 2>/dev/null || true
trap - EXIT
if [ -s "$WORK_DIR/candump.err" ]; then
  echo "smoke: candump's messages (expected: the interface going down):"
  sed 's/^/  /' "$WORK_DIR/candump.err"
fi
# Leave vcan0 as found (it may be the host's own in --mode host).
{ ip link set dev vcan0 down && ip link set dev vcan0 mtu 72 && ip link set dev vcan0 up; } ||
  fail "could not restore vcan0 to mtu 72"
cp "$log" "$OUT_DIR/candump.log"
echo "smoke: PASS"
