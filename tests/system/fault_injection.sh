#!/bin/sh
# System test: fault injection in the guest, one boot. The installed, hardened
# unit (systemd/pumpthermd.service, /usr/sbin/pumpthermd) runs three pumps of the plant's demo
# recording, replayed on vcan0 by a feeder (canplayer) for 80 s while faults are injected; after
# each fault the test checks what the daemon did:
#   1. vcan0 down and up four times while frames flow, then deleted and re-created: the same
#      process keeps running and resumes by itself (each down and up logged exactly once); at
#      the end, the daemon received or counted as a receive-queue drop at least every frame a
#      reference receiver (candump -d, a socket of its own) got or counted as dropped, and no
#      more than the feeder and the flood wrote (canplayer -v lists the frames it wrote; it
#      stops at the first one the kernel refuses, and the feeder resumes after it);
#   2. a flood of malformed frames amid the valid traffic (short frames on mapped IDs, unknown
#      standard and extended IDs, remote frames, CAN FD frames short or unknown or carrying
#      "not available" values, error frames that take GW_HEALTH.BusState to passive and back):
#      counted as unknown / bad length / error frames in the status line, no crash;
#   3. LCM sends failing (the multicast route deleted for 4 s of sleeps, 6-9 s under TCG): counted
#      ('lcm N sent, M failed' in the status line), logged once (rate-limited), and LCM resumes
#      by itself when the route is back (an lcm-logger in the guest receives again, and nothing
#      with a receive time inside the window in which the daemon's sends were failing);
#   4. the state directory full (a 256 KiB tmpfs mounted on /var/lib/private/pumptherm before the
#      unit starts, filled with dd): the write fails cleanly (logged once, counted), the old
#      state.toml stays byte for byte, a kill -9 while full restarts the daemon with that file
#      restored, and once space returns the next write succeeds (logged);
#   5. kill -9 during state writes (gateway.test_state_write_pause_s = 0.4 stops each write
#      halfway through its temporary for 0.4 s): eight kills, four when the temporary exists,
#      four at other moments; after each, systemd restarts the daemon, state.toml is complete,
#      the restarted daemon restores 3 pumps from it and removes the cut-short temporary
#      (logged), never reads it; the first GW_TEMPS_A after the last restart carries the
#      temperatures from before the kills (a cold start sends "not available").
# Throughout: every GW_TEMPS_A/B frame the daemon sent (candump) decoded with the DBC scaling is
# "not available" (0xFFFF) exactly where the offline run of the recording has no value, and
# otherwise within 5 K of the range the offline run's frames span for that pump and signal (the
# replay pauses during faults 4 and 5, and the daemon, rightly, ages its estimates with the
# pumps' last inputs over each restart: up to 3.1 K beyond that range seen after a minute of
# kills); no unexpected restart (NRestarts counts the kills only).
# Runs as root in the guest (tests/system/run_system_test.sh); vcan0 is up, lo has 224.0.0.0/4.
set -eu
T=fault_injection
unit=pumpthermd.service
cfg=/etc/pumptherm/pumpthermd.toml
state_dir=/var/lib/private/pumptherm
state=$state_dir/state.toml
lcm_url='udpm://239.255.76.67:7667?ttl=0'
W=$WORK_DIR
t_start=$(date +%s.%N)

show() { systemctl show -p "$1" --value "$unit"; }
# fail MESSAGE: on stderr, so that a failure inside $(...) is seen too (set -e then stops).
fail() {
  {
    echo "$T: FAIL: $*"
    echo "--- systemctl status $unit"
    systemctl status --no-pager --full "$unit" 2>&1 | sed 's/^/  /' || true
    echo "--- journalctl -u $unit (last 80 lines)"
    journalctl -u "$unit" --no-pager -o short-monotonic 2>&1 | tail -n 80 | sed 's/^/  /' || true
  } >&2
  journalctl -u "$unit" --no-pager -o short-monotonic >"$OUT_DIR/journal.txt" 2>&1 || true
  cp "$W"/cap*.log "$W"/ref*.log "$W"/ref*.err "$W"/feed_*.txt "$OUT_DIR/" 2>/dev/null || true
  exit 1
}
say() { echo "$T: [$(awk -v a="$t_start" -v b="$(date +%s.%N)" 'BEGIN { printf "%5.1f", b - a }') s] $*"; }
# wait_for SECONDS COMMAND...: polls COMMAND every 0.2 s until it succeeds, for up to SECONDS
# of the clock (a poll that runs systemctl can itself take a second under TCG).
wait_for() {
  end=$(($(date +%s) + $1)); shift
  until "$@"; do
    [ "$(date +%s)" -le "$end" ] || return 1
    sleep 0.2
  done
}
now() { date +%s.%N | cut -c1-17; }
running() { [ "$(show ActiveState)/$(show SubState)" = active/running ]; }
new_pid() { p=$(show MainPID); [ "$p" -gt 0 ] && [ "$p" != "$1" ] && running; }
journal_count() { journalctl -u "$unit" --no-pager -o cat | grep -c -- "$1" || true; }
journal_has_n() { [ "$(journal_count "$1")" -ge "$2" ]; }
# snap: the unit's StatusText (the daemon's status line, every 0.5 s here) into S;
# sv NAME: a number from S; st NAME: both (one systemctl call: a second or so under TCG).
snap() { S=$(show StatusText); }
sv() {
  case $1 in
    rx) re='.*rx \([0-9]*\) frames.*' ;;
    drops) re='.*, \([0-9]*\) rx drops.*' ;;
    txdrop) re='.* \([0-9]*\) tx dropped.*' ;;
    unknown) re='.*; \([0-9]*\) unknown,.*' ;;
    bad) re='.* \([0-9]*\) bad length.*' ;;
    errf) re='.* \([0-9]*\) error frames.*' ;;
    lcm_sent) re='.*lcm \([0-9]*\) sent.*' ;;
    lcm_failed) re='.*lcm [0-9]* sent, \([0-9]*\) failed.*' ;;
    saved) re='.*state \([0-9]*\) saved.*' ;;
    save_failed) re='.*state [0-9]* saved, \([0-9]*\) failed.*' ;;
  esac
  v=$(echo "$S" | sed -n "s/^$re\$/\\1/p")
  [ -n "$v" ] || fail "no '$1' in StatusText '$S'"
  echo "$v"
}
st() { snap; sv "$1"; }
st_ge() { [ "$(st "$1")" -ge "$2" ]; }
st_gt() { [ "$(st "$1")" -gt "$2" ]; }
# check_state FILE WHAT: a complete saved state of the three pumps (every key of every pump,
# the header, a final newline); its size in state_size.
check_state() {
  [ -s "$1" ] || fail "$2: $1 is missing or empty"
  head -n 1 "$1" | grep -q '^# pumpthermd saved state' || fail "$2: $1 lacks its header line"
  grep -q '^version = 2$' "$1" || fail "$2: $1 lacks 'version = 2'"
  for key in model time_us x_degC s_K2 resistance_x resistance_p resistance_moments resistance_blocks \
             resistance_rejections resistance_probability latched_trip_nodes latched_trip_values_degC; do
    [ "$(grep -c "^ *$key = " "$1")" = 3 ] || fail "$2: $1 does not have '$key' for 3 pumps"
  done
  for p in pump1 pump2 pump3; do grep -q "^\[pump\.$p\]" "$1" || fail "$2: $1 lacks [pump.$p]"; done
  [ "$(tail -c 1 "$1" | od -An -c | tr -d ' ')" = '\n' ] || fail "$2: $1 does not end with a newline"
  state_size=$(wc -c <"$1")
}

# --- setup ----------------------------------------------------------------------------------
mkdir -p /usr/share/pumptherm/dbc /usr/share/pumptherm/models /usr/share/pumptherm/motors /etc/pumptherm
cp "$DATA_DIR/pumptherm.dbc" "$DATA_DIR/mapping_pumptherm.toml" /usr/share/pumptherm/dbc/
cp "$DATA_DIR/tmp-generic.toml" /usr/share/pumptherm/models/
cp "$DATA_DIR/han2019-tmp.toml" /usr/share/pumptherm/motors/
# The demo's configuration on vcan0 with error frames, LCM on (the demo's URL), the status line
# every 0.5 s, the state saved every second.
sed -e 's/^interface = "can0"/interface = "vcan0"\nerror_frames = true/' \
    -e 's/^thermal_period_s = 1.0/thermal_period_s = 1.0\nstatus_period_s = 0.5\nstate_save_period_s = 1.0/' \
    "$DATA_DIR/pumpthermd-demo.toml" >"$cfg"
chmod 0644 "$cfg"
grep -q "^url = \"$lcm_url\"" "$cfg" || fail "the demo configuration no longer has LCM on $lcm_url"
/usr/sbin/pumpthermd --check-config "$cfg" || fail "the test configuration is invalid"

# The state directory on a small file system of its own (fault 4), there before the unit first
# starts (systemd gives it to the dynamic user; a mount made later would not reach into the
# unit's own mount namespace).
mkdir -p -m 0700 /var/lib/private
mkdir -p "$state_dir"
mount -t tmpfs -o size=256k,mode=0700 pumptherm-state "$state_dir" || fail "cannot mount a tmpfs on $state_dir"

# part FROM TO: the recording's frames with FROM <= t - t0 < TO, its can0 named vcan0.
part() {
  awk -v a="$1" -v b="$2" 'NR == 1 { t0 = substr($1, 2) + 0 }
    { t = substr($1, 2) + 0 - t0 } t >= a && t < b { sub(/ can0 /, " vcan0 "); print }' "$DATA_DIR/pipeline.log"
}
# The feeder's input in chunks of 5 s (it stops between two when told), 0-90 s at most.
c=0
while [ "$c" -lt 18 ]; do part $((c * 5)) $((c * 5 + 5)) >"$W/chunk$(printf %02d "$c").log"; c=$((c + 1)); done
part 90 90.5 >"$W/burst1.log"
part 90.5 91 >"$W/burst2.log"
part 0 100 >"$W/whole.log"

# The reference: the offline run of the whole recording (same binary, same configuration).
/usr/sbin/pumpthermd --config "$cfg" -r "$W/whole.log" --output-log "$W/offline.log" >"$W/offline.txt" 2>&1 ||
  fail "the offline run failed: $(cat "$W/offline.txt")"
# Per pump (1..3) and signal (TEMPS_A fields 0..3 = 0..3, TEMPS_B fields 0..3 = 4..7): min and
# max in degC, or "na" when the offline run never had a value there.
decode_temps='
  function hex(s) { return h[tolower(s)] }
  BEGIN { for (i = 0; i < 256; i++) h[sprintf("%02x", i)] = i }
  { split($3, f, "#"); id = f[1]; p = f[2] }
  id ~ /^4[01][123]$/ {
    pump = substr(id, 3, 1) + 0; base = (substr(id, 2, 1) == "1") ? 4 : 0
    for (k = 0; k < 4; k++) {
      raw = hex(substr(p, 4 * k + 1, 2)) + 256 * hex(substr(p, 4 * k + 3, 2))
      emit(substr($1, 2, length($1) - 2) + 0, pump, base + k, raw)
    }
  }'
awk "$decode_temps"'
  function emit(t, pump, sig, raw) {
    key = pump " " sig; seen[key] = 1
    if (raw == 65535) return
    v = raw * 0.01 - 50
    if (!(key in lo) || v < lo[key]) lo[key] = v
    if (!(key in hi) || v > hi[key]) hi[key] = v
  }
  END { for (k in seen) print k, (k in lo) ? lo[k] : "na", (k in hi) ? hi[k] : "na" }' "$W/offline.log" | sort >"$W/envelope.txt"
[ "$(wc -l <"$W/envelope.txt")" = 24 ] || fail "the offline run did not send GW_TEMPS_A/B for 3 pumps: $(cat "$W/envelope.txt")"
say "offline reference: $(head -n 1 "$W/offline.txt"); ranges (pump signal min max): $(grep -v na "$W/envelope.txt" | tr '\n' ';')"

# Captures of the gateway's temperature, identification and health frames for the whole test
# (-D: on through down/up; a deleted interface ends candump: a second capture after it).
candump -D -r 8388608 -L vcan0,400:7C0,600:7F0 >"$W/cap1.log" 2>"$W/cap1.err" &
cap_pid=$!
# A reference receiver beside the daemon: a socket of its own on vcan0 for every frame the
# writers send (standard IDs 0x100-0x1FF, any extended ID; not the daemon's 0x4xx-0x7xx, not error
# frames), counting its own receive-queue drops (-d). What reached it reached the sockets.
candump -D -d -r 8388608 -L vcan0,100:700,80000000:80000000 >"$W/ref1.log" 2>"$W/ref1.err" &
ref_pid=$!
# (lcm-logger 1.3.1 lists -l in its help but accepts only --lcm-url.)
lcm-logger -q -f --lcm-url="$lcm_url" "$W/lcm.log" >"$W/lcm-logger.err" 2>&1 &
logger_pid=$!
sleep 0.5

systemctl start "$unit" || fail "systemctl start failed"
running || fail "not running after start"
pid1=$(show MainPID)
say "started: MainPID $pid1, state directory on $(df -h "$state_dir" | awk 'NR == 2 { print $1 ", " $2 }')"

# --- the feeder: plays the chunks onto vcan0, resuming after each frame the kernel refuses ----
# canplayer -v prints each frame it wrote; at the first write that fails (interface down or
# gone) it exits. The feeder then skips that frame (it was never on the bus), waits until vcan0
# is up and the test allows (file feed_go), and plays the rest. It stops after the chunk under
# way when the file feed_stop appears. feed_runs.txt: frames written, exit status, time, chunk.
feed() {
  rest=$W/feed_rest.log
  : >"$W/feed_runs.txt"
  for chunk in "$W"/chunk*.log; do
    [ ! -e "$W/feed_stop" ] || break
    cp "$chunk" "$rest"
    while [ -s "$rest" ]; do
      until [ -e "$W/feed_go" ] && ip link show vcan0 2>/dev/null | grep -q '[<,]UP[,>]'; do sleep 0.05; done
      rc=0
      canplayer -v -I "$rest" >"$W/feed_out.txt" 2>>"$W/feed_err.txt" || rc=$?
      n=$(grep -c '^ *vcan0 (vcan0) ' "$W/feed_out.txt" || true)
      cat "$W/feed_out.txt" >>"$W/feed_all.txt"
      echo "$n $rc $(date +%s.%N) $(basename "$chunk")" >>"$W/feed_runs.txt"
      [ "$rc" -ne 0 ] || break
      tail -n +$((n + 2)) "$rest" >"$rest.next"
      mv "$rest.next" "$rest"
    done
  done
  touch "$W/feed_done"
}
# The kernel's own drops on vcan0: frames can_send accepted from a writer whose local echo
# netif_rx then dropped before any socket saw them (rx_dropped: the device no longer running
# while it goes down, or the CPU backlog full). Reset when vcan0 is re-created.
kernel_drops() { cat /sys/class/net/vcan0/statistics/rx_dropped; }
feed_sent() { awk '{ n += $1 } END { print n + 0 }' "$W/feed_runs.txt"; }
touch "$W/feed_go"
feed &
feed_pid=$!
sleep 3

# --- 1. vcan0 down and up, then deleted and re-created -------------------------------------
kd_cycles=""
for cycle in 1 2 3 4; do
  ip link set vcan0 down
  sleep 1.5
  kd_cycles="$kd_cycles $(kernel_drops)"
  ip link set vcan0 up
  sleep 2.5
done
wait_for 10 journal_has_n 'vcan0: interface is up again' 4 || fail "the daemon did not see vcan0 come up 4 times"
downs=$(journal_count 'vcan0: interface is down'); ups=$(journal_count 'vcan0: interface is up again')
say "1. four down/up cycles of 1.5 s: the journal has $downs 'interface is down' and $ups 'up again' lines; $(wc -l <"$W/feed_runs.txt") canplayer runs so far; tx dropped $(st txdrop); vcan0 rx_dropped after each down:$kd_cycles"
[ "$downs" = 4 ] && [ "$ups" = 4 ] || fail "want exactly 4 down and 4 up lines (a flapping link state?), got $downs and $ups"
[ "$(show MainPID)" = "$pid1" ] || fail "MainPID changed during the down/up cycles"
[ "$(st txdrop)" -gt 0 ] || fail "no send failed while vcan0 was down (tx dropped 0)"

rm -f "$W/feed_go"  # the feeder waits after the frame the deletion makes it fail on
kdrops_before_del=$(kernel_drops)
t_del=$(now)
ip link del dev vcan0
wait_for 10 journal_has_n 'vcan0: interface was removed' 1 || fail "the daemon did not notice vcan0 being removed"
sleep 1.5
ip link add dev vcan0 type vcan
ip link set vcan0 up
t_add=$(now)
wait_for 10 journal_has_n 'vcan0: interface is back; socket reopened' 1 || fail "the daemon did not reopen vcan0"
t_reopen=$(now)
candump -D -r 8388608 -L vcan0,400:7C0,600:7F0 >"$W/cap2.log" 2>"$W/cap2.err" &
cap_pid=$!
candump -D -d -r 8388608 -L vcan0,100:700,80000000:80000000 >"$W/ref2.log" 2>"$W/ref2.err" &
ref_pid=$!
sleep 0.3
touch "$W/feed_go"
say "1. vcan0 deleted, re-created $(awk -v a="$t_del" -v b="$t_add" 'BEGIN { printf "%.1f", b - a }') s later; socket reopened $(awk -v a="$t_add" -v b="$t_reopen" 'BEGIN { printf "%.1f", b - a }') s after that (journal: $(journalctl -u "$unit" -o cat | grep 'interface was removed' | tail -n 1))"
[ "$(show MainPID)" = "$pid1" ] || fail "MainPID changed across the deletion of vcan0"
[ "$(show NRestarts)" = 0 ] || fail "NRestarts=$(show NRestarts) after fault 1, want 0"
sleep 3

# --- 2. a flood of malformed frames amid the valid traffic -----------------------------------
snap; u0=$(sv unknown); b0=$(sv bad); e0=$(sv errf)
t_flood=$(now)
flood_n=0
flood() {  # flood COUNT cangen-arguments...
  count=$1; shift
  cangen -g 1 -n "$count" "$@" vcan0 || fail "cangen $* failed"
  flood_n=$((flood_n + count))
}
flood 1000 -e -I r -L r          # unknown: random 29-bit IDs
flood 300 -I 123 -L 8            # unknown: a standard ID no pump uses
flood 300 -I 101 -L 4            # bad length: PUMP_FAST_I of pump1, 4 of 8 bytes
flood 300 -I 183 -L 2            # bad length: PUMP_STATUS of pump3, 2 of 8 bytes
flood 200 -R -I 102              # remote frames on PUMP_FAST_I of pump2: ignored
flood 200 -f -I 124 -L 64        # CAN FD, unknown ID, 64 bytes
flood 200 -f -I 112 -L 6         # CAN FD on PUMP_FAST_U of pump2, 6 bytes: bad length
n_na=0
while [ "$n_na" -lt 10 ]; do     # CAN FD PUMP_FAST_I of pump1 with "not available" currents
  cansend vcan0 101##0008000800000000000000000 || fail "cansend (CAN FD) failed"
  n_na=$((n_na + 1))
done
flood_n=$((flood_n + n_na))
n_err=0
while [ "$n_err" -lt 20 ]; do    # error frames: protocol violations (CAN_ERR_PROT)
  cansend vcan0 20000008#0000000000000000 || fail "cansend (error frame) failed"
  n_err=$((n_err + 1))
done
cansend vcan0 20000004#0010000000000000 || fail "cansend (controller error frame) failed"  # RX passive
t_passive=$(now)
sleep 2.5
cansend vcan0 20000004#0040000000000000 || fail "cansend (controller error frame) failed"  # active again
t_active=$(now)
n_err=$((n_err + 2))
flood_s=$(awk -v a="$t_flood" -v b="$t_active" 'BEGIN { printf "%.1f", b - a }')
expect_u=1500; expect_b=800
wait_for 10 st_ge errf $((e0 + n_err)) || fail "error frames: $(st errf), want $((e0 + n_err))"
wait_for 10 st_ge unknown $((u0 + expect_u)) || true
snap
du=$(($(sv unknown) - u0)); db=$(($(sv bad) - b0)); de=$(($(sv errf) - e0)); drops=$(sv drops)
say "2. flood of $flood_n malformed frames + $n_err error frames in $flood_s s: status line +$du unknown (want $expect_u), +$db bad length (want $expect_b), +$de error frames (want $n_err); rx drops so far $drops"
if [ "$drops" = 0 ]; then
  [ "$du" = "$expect_u" ] && [ "$db" = "$expect_b" ] || fail "unknown/bad length counts differ with no frame dropped"
else
  [ "$du" -le "$expect_u" ] && [ "$db" -le "$expect_b" ] || fail "more unknown/bad length frames counted than sent"
fi
[ "$de" = "$n_err" ] || fail "error frames counted $de, sent $n_err"
[ "$(show MainPID)" = "$pid1" ] || fail "MainPID changed during the flood"

# --- 3. LCM sends failing while CAN flows ----------------------------------------------------
# Status snapshots: A a second into the outage, B at its end, C a second after it, D later.
snap; [ "$(sv lcm_sent)" -gt 0 ] && [ "$(sv lcm_failed)" = 0 ] || fail "LCM not working before the outage: $S"
t_route_del=$(now)
ip route del 224.0.0.0/4 dev lo
sleep 1.5
snap; lsA=$(sv lcm_sent); lfA=$(sv lcm_failed)
sleep 2.5
t_snapB=$(now)
snap; lsB=$(sv lcm_sent); lfB=$(sv lcm_failed)
ip route add 224.0.0.0/4 dev lo
t_route_add=$(now)
sleep 1.5
snap; lsC=$(sv lcm_sent); lfC=$(sv lcm_failed)
sleep 2
snap; lsD=$(sv lcm_sent); lfD=$(sv lcm_failed)
say "3. route to 224.0.0.0/4 deleted for $(awk -v a="$t_route_del" -v b="$t_route_add" 'BEGIN { printf "%.1f", b - a }') s: status line 'lcm N sent, M failed' during the outage $lsA/$lfA -> $lsB/$lfB, after it $lsC/$lfC -> $lsD/$lfD; journal: $(journalctl -u "$unit" -o cat | grep 'LCM: cannot send' | head -n 1) / $(journalctl -u "$unit" -o cat | grep 'LCM: sending works again' | tail -n 1)"
[ "$lsA" = "$lsB" ] || fail "LCM messages counted as sent while the route was gone ($lsA -> $lsB)"
[ "$lfB" -gt "$lfA" ] || fail "no LCM failure counted while the route was gone ($lfA -> $lfB)"
[ "$lfC" = "$lfD" ] || fail "LCM still failing after the route came back ($lfC -> $lfD)"
[ "$lsD" -gt "$lsC" ] || fail "LCM did not resume after the route came back ($lsC -> $lsD)"
journal_has_n 'LCM: sending works again' 1 || fail "no 'LCM: sending works again' line after the route came back"
[ "$(journal_count 'LCM: cannot send')" = 1 ] || fail "want one 'LCM: cannot send' line (rate-limited), got $(journal_count 'LCM: cannot send')"
[ ! -e "$W/feed_done" ] || fail "the feeder had played all 90 s before the LCM check ended: CAN did not flow throughout (a very slow guest?)"
[ "$(show MainPID)" = "$pid1" ] || fail "MainPID changed during the LCM outage"

# --- accounting of faults 1-3 (same process throughout) -------------------------------------
touch "$W/feed_stop"
wait_for 30 test -e "$W/feed_done" || fail "the feeder did not stop"
sleep 1
kill "$logger_pid" 2>/dev/null || true  # SIGTERM: it flushes and exits (SIGINT is ignored in background)
wait "$logger_pid" 2>/dev/null || true
sent=$(feed_sent)
played=$(cat $(awk '{ print "'"$W"'/" $4 }' "$W/feed_runs.txt" | sort -u) | wc -l)
kdrops=$((kdrops_before_del + $(kernel_drops)))
# vcan0's rx_dropped counts every frame netif_rx dropped before any socket saw it, the daemon's
# own GW_* frames among them (a send accepted just as the link goes down), which the writers'
# counts do not include. Frames can also go before any socket without a count (e.g. still in the
# CPU's backlog when vcan0 is deleted). The reference receiver tells what reached the sockets:
# the daemon must have received or counted as dropped at least every frame the reference did
# (nothing lost that could arrive), and no more than were written (nothing counted twice).
written=$((sent + flood_n))
kill "$ref_pid" 2>/dev/null || true  # SIGTERM: candump ends its loop and flushes
wait "$ref_pid" 2>/dev/null || true
ref_rx=$(cat "$W/ref1.log" "$W/ref2.log" | grep -c '^(' || true)
ref_drops=0
for f in ref1 ref2; do
  d=$(cat "$W/$f.log" "$W/$f.err" | sed -n 's/.*total drops \([0-9]*\).*/\1/p' | tail -n 1)
  ref_drops=$((ref_drops + ${d:-0}))
done
ref_total=$((ref_rx + ref_drops))
settled() { snap; [ $(($(sv rx) + $(sv drops))) -ge "$ref_total" ]; }
wait_for 20 settled || true
sleep 1
snap; rx=$(sv rx); drops=$(sv drops)
say "accounting: the feeder wrote $sent of the $played frames of the first $(($(cut -d' ' -f4 "$W/feed_runs.txt" | sort -u | wc -l) * 5)) s of the recording in $(wc -l <"$W/feed_runs.txt") canplayer runs ($((played - sent)) refused while vcan0 was down or gone), the flood $flood_n non-error frames: $written written; vcan0 rx_dropped $kdrops ($kdrops_before_del before the deletion); the reference receiver got $ref_rx and counted $ref_drops drops, $ref_total in all ($((written - ref_total)) of the written never reached it); the daemon received $rx and counted $drops receive-queue drops, $((rx + drops)) in all"
if [ $((rx + drops)) -lt "$ref_total" ] || [ $((rx + drops)) -gt "$written" ]; then
  # Which IDs: the daemon's per-ID counts (its summary at stop) against what was written.
  systemctl stop "$unit"
  awk '{ n[$3]++ } END { for (k in n) print k, n[k] }' "$W/feed_all.txt" | sort >"$W/ids_fed.txt"
  journalctl -u "$unit" -o cat | awk '$1 == "vcan0" && $2 ~ /^[0-9A-F]+$/ { print $2, $3 }' | sort >"$W/ids_rx.txt"
  cat "$W/ref1.log" "$W/ref2.log" | awk '/^\(/ { split($3, f, "#"); n[f[1]]++ } END { for (k in n) print k, n[k] }' | sort >"$W/ids_ref.txt"
  echo "per ID, written by the feeder, received by the daemon, received by the reference (the flood's IDs come on top):" >&2
  join -a 1 -a 2 "$W/ids_fed.txt" "$W/ids_rx.txt" | join -a 1 -a 2 - "$W/ids_ref.txt" | grep -v '^[0-9A-F]\{8\} ' >&2 || true
  fail "received $rx + dropped $drops is outside $ref_total (the reference receiver's) .. $written (written)"
fi
[ "$(show MainPID)" = "$pid1" ] && [ "$(show NRestarts)" = 0 ] || fail "the daemon was restarted during faults 1-3"
# LCM as received by lcm-logger (the event headers of its log: receive time, channel).
# The window in which no send can have worked, on the guest's realtime clock (lcm-logger's and
# the journal's): from the daemon's first failed send (its journal line; journald stamps a line
# when it gets it, so the failure came no later) plus 0.5 s (a message sent just before may be
# received, and stamped, a little later) to 0.5 s before snapshot B (StatusText is at most
# 0.5 s old), which still counted no more sent; with one 'sending works again' line (after B)
# no send worked in between. The test's t_route_del..t_route_add is wider: ip itself takes a
# while under TCG, and messages sent before the route went are received in it.
[ "$(journal_count 'LCM: sending works again')" = 1 ] || fail "want one 'LCM: sending works again' line, got $(journal_count 'LCM: sending works again')"
jtime() { journalctl -u "$unit" --no-pager -o short-unix | grep -- "$1" | head -n 1 | cut -d' ' -f1; }
t_lcm_fail=$(jtime 'LCM: cannot send'); t_lcm_back=$(jtime 'LCM: sending works again')
[ -n "$t_lcm_fail" ] && [ -n "$t_lcm_back" ] || fail "no journal time of the LCM outage"
w_from=$(awk -v t="$t_lcm_fail" 'BEGIN { printf "%.6f", t + 0.5 }'); w_to=$(awk -v t="$t_snapB" 'BEGIN { printf "%.6f", t - 0.5 }')
awk -v a="$w_from" -v b="$w_to" 'BEGIN { exit !(b - a >= 2.0) }' || fail "the LCM check window $w_from..$w_to is shorter than 2 s"
od -An -v -tx1 -w1 "$W/lcm.log" | awk -v a="$w_from" -v b="$w_to" '
  BEGIN { for (i = 0; i < 256; i++) h[sprintf("%02x", i)] = i }
  { x[n++] = h[$1] }
  function be(at, len,   v, k) { v = 0; for (k = 0; k < len; k++) v = v * 256 + x[at + k]; return v }
  END {
    i = 0
    while (i + 28 <= n) {
      if (be(i, 4) != 3986807297) { print "bad sync at byte " i; exit 1 }  # 0xEDA1DA01
      t = be(i + 12, 8) / 1e6; cl = be(i + 20, 4); dl = be(i + 24, 4)
      if (t < a) before++; else if (t <= b) during++; else after++
      i += 28 + cl + dl
    }
    printf "%d %d %d\n", before, during, after
  }' >"$W/lcm_counts.txt" || fail "the LCM log does not parse: $(cat "$W/lcm_counts.txt")"
read -r lcm_before lcm_during lcm_after <"$W/lcm_counts.txt"
say "3. the daemon's sends failed from $t_lcm_fail to $t_lcm_back by the journal ($(awk -v a="$t_lcm_fail" -v b="$t_lcm_back" 'BEGIN { printf "%.1f", b - a }') s; route gone $t_route_del..$t_route_add); lcm-logger received $lcm_before messages before $w_from, $lcm_during in $w_from..$w_to ($(awk -v a="$w_from" -v b="$w_to" 'BEGIN { printf "%.1f", b - a }') s), $lcm_after after ($(wc -c <"$W/lcm.log") bytes; its stderr: $(tr '\n' ' ' <"$W/lcm-logger.err"))"
[ "$lcm_before" -gt 0 ] && [ "$lcm_after" -gt 0 ] || fail "LCM not received before and after the outage"
[ "$lcm_during" = 0 ] || fail "LCM messages received while the daemon's sends were failing"

# --- 4. the state directory full -------------------------------------------------------------
check_state "$state" "before the fill"
sf0=$(st save_failed)
dd if=/dev/zero of="$state_dir/filler" bs=4096 2>/dev/null || true
say "4. state directory filled: $(df -k "$state_dir" | awk 'NR == 2 { print $4 " KiB available, " $3 " KiB used" }')"
# Once a failed write is counted, no write that began before the fill is still under way.
wait_for 15 st_ge save_failed "$((sf0 + 1))" || fail "no failed state write counted: $(show StatusText)"
cp "$state" "$W/state_at_fill.toml"
wait_for 15 st_ge save_failed "$((sf0 + 4))" || fail "failed state writes not counted: $(show StatusText)"
journal_has_n 'state not saved: cannot write' 1 || fail "no 'state not saved: cannot write ...' line"
cmp -s "$state" "$W/state_at_fill.toml" || fail "state.toml changed while the file system was full"
check_state "$state" "while full"
[ "$(journal_count 'state not saved')" = 1 ] || fail "want one 'state not saved' line (rate-limited), got $(journal_count 'state not saved')"
say "4. $(($(st save_failed) - sf0)) failed writes counted, one journal line: $(journalctl -u "$unit" -o cat | grep 'state not saved' | head -n 1)"
if [ -e "$state.tmp" ]; then  # a write under way at this instant, or one left behind?
  sleep 0.3
  [ ! -e "$state.tmp" ] || fail "a failed write left state.toml.tmp behind"
fi
# kill -9 while full: the restarted daemon restores the intact file.
restored0=$(journal_count 'restored the state of 3 pump(s)')
kill -9 "$pid1"
wait_for 30 new_pid "$pid1" || fail "not restarted within 30 s of kill -9 (disk full)"
pid2=$(show MainPID)
wait_for 15 journal_has_n 'restored the state of 3 pump(s)' $((restored0 + 1)) || fail "the daemon restarted on a full disk did not restore 3 pumps"
wait_for 10 journal_has_n 'state not saved' 2 || fail "the restarted daemon did not report its failed writes"
rm -f "$state_dir/filler"
t_space=$(now)
wait_for 15 journal_has_n 'state saved again' 1 || fail "no 'state saved again' after space returned"
wait_for 10 sh -c "! cmp -s '$state' '$W/state_at_fill.toml'" || fail "state.toml not rewritten after space returned"
check_state "$state" "after space returned"
say "4. kill -9 while full: restarted as $pid2, $(journalctl -u "$unit" -o cat | grep 'restored the state' | tail -n 1); space back: $(journalctl -u "$unit" -o cat | grep 'state saved again' | tail -n 1); state.toml $state_size bytes, complete"

# --- 5. kill -9 during state writes ----------------------------------------------------------
sed -i 's/^state_save_period_s = 1.0/state_save_period_s = 1.0\ntest_state_write_pause_s = 0.4/' "$cfg"
/usr/sbin/pumpthermd --check-config "$cfg" || fail "the configuration with test_state_write_pause_s is invalid"
reloads0=$(journal_count 'configuration reloaded')
systemctl reload "$unit" || fail "systemctl reload failed"
wait_for 15 journal_has_n 'configuration reloaded' $((reloads0 + 1)) || fail "the reload with the write pause was not applied"
canplayer -I "$W/burst1.log" || fail "canplayer (burst 1) failed"
sleep 1.5
t_kills=$(now)
pid=$(show MainPID)
kills=0; mid=0; left_tmp=0
restored0=$(journal_count 'restored the state of 3 pump(s)')
removed0=$(journal_count 'the unfinished state write of an earlier run')
while [ "$kills" -lt 8 ]; do
  if [ $((kills % 2)) = 0 ]; then  # in a write: as soon as the temporary is there
    n=0
    until [ -e "$state.tmp" ]; do
      n=$((n + 1)); [ "$n" -le 200 ] || fail "kill $((kills + 1)): no state write in progress within 10 s"
      sleep 0.05
    done
  else                             # at another moment (1.1 to 1.9 s after the restore)
    sleep "1.$((kills * 3 % 10))"
  fi
  kill -9 "$pid"
  while kill -0 "$pid" 2>/dev/null; do sleep 0.05; done
  kills=$((kills + 1))
  note="no write in progress"
  if [ -e "$state.tmp" ]; then
    left_tmp=$((left_tmp + 1))
    note="killed in a write: state.toml.tmp $(wc -c <"$state.tmp") bytes"
  fi
  check_state "$state" "after kill $kills"
  cp "$state" "$W/state_after_kill.toml"  # what the restarted daemon restores
  wait_for 30 new_pid "$pid" || fail "kill $kills: not restarted within 30 s"
  pid=$(show MainPID)
  wait_for 15 journal_has_n 'restored the state of 3 pump(s)' $((restored0 + kills)) ||
    fail "kill $kills: the restarted daemon did not restore 3 pumps"
  say "5. kill $kills: $note; state.toml complete ($state_size bytes); restarted as $pid, restored 3 pumps"
done
removed=$(($(journal_count 'the unfinished state write of an earlier run') - removed0))
say "5. $kills kills, $left_tmp in a write; the restarts removed $removed cut-short temporaries: $(journalctl -u "$unit" -o cat | grep 'unfinished state write' | tail -n 1)"
[ "$left_tmp" -ge 4 ] || fail "only $left_tmp of the kills landed in a write"
[ "$removed" = "$left_tmp" ] || fail "$left_tmp temporaries left, $removed removed at restart"
t_last=$(now)
canplayer -I "$W/burst2.log" || fail "canplayer (burst 2) failed"
sleep 2
[ "$(show NRestarts)" = $((kills + 1)) ] || fail "NRestarts=$(show NRestarts), want $((kills + 1)) (the kills only)"
[ "$(journal_count 'no saved state in')" = 1 ] || fail "a cold start after the first one"
for bad in 'saved state ignored' 'does not parse' 'is damaged' 'unknown version'; do
  [ "$(journal_count "$bad")" = 0 ] || fail "the journal has '$bad': $(journalctl -u "$unit" -o cat | grep "$bad" | head -n 1)"
done

systemctl stop "$unit" || fail "systemctl stop failed"
[ "$(show Result)" = success ] || fail "Result=$(show Result) after stop, want success"
kill "$cap_pid" 2>/dev/null || true
wait "$cap_pid" 2>/dev/null || true
journalctl -u "$unit" --no-pager -o short-monotonic >"$OUT_DIR/journal.txt" 2>&1 || true
cat "$W/cap1.log" "$W/cap2.log" >"$W/cap.log"
cp "$W/cap.log" "$OUT_DIR/frames.log"
cp "$W/feed_runs.txt" "$W/envelope.txt" "$W/state_after_kill.toml" "$OUT_DIR/"

# The state came back on the bus: the first GW_TEMPS_A of each pump after the last restart
# (before its first thermal step) carries the frame node of the state.toml it restored, aged
# over the restart (a cold start sends "not available"). The ageing is the model's prediction
# with held inputs, the same that moved the frame node over the kills, so the first value sent
# may differ from the restored one by that drift rate times the gap between the state's save
# and the first frame (5-10 s on a loaded machine), plus 0.25 K. Against the last frame before
# the kills it has moved by the model's prediction over the kills (held inputs, a minute).
frame_of() {  # frame_of ID FROM TO first|last: "PAYLOAD TIME_S" of that GW_TEMPS_A
  awk -v id="$1" -v a="$2" -v b="$3" -v which="$4" '
    { ts = substr($1, 2, length($1) - 2); t = ts + 0; split($3, f, "#") }
    f[1] == id && t > a && t < b { p = f[2] " " ts; if (which == "first") { print p; exit } }
    END { if (which == "last" && p != "") print p }' "$W/cap.log"
}
degC() { awk -v p="$1" -v k="$2" 'BEGIN { for (i = 0; i < 256; i++) h[sprintf("%02X", i)] = i
  r = h[toupper(substr(p, 4 * k + 1, 2))] + 256 * h[toupper(substr(p, 4 * k + 3, 2))]
  if (r == 65535) print "n/a"; else printf "%.2f", r * 0.01 - 50 }'; }
saved_frame() {  # saved_frame PUMP: the frame node (the model's first) in state_after_kill.toml
  awk -v want="[pump.$1]" '$0 == want { on = 1; next } /^\[/ { on = 0 }
    on && /^ *x_degC = \[ / { sub(/^ *x_degC = \[ */, ""); split($0, v, ","); printf "%.2f", v[1]; exit }' "$W/state_after_kill.toml"
}
saved_time_s() {  # saved_time_s PUMP: the wall time of that pump's saved state, in s
  awk -v want="[pump.$1]" '$0 == want { on = 1; next } /^\[/ { on = 0 }
    on && /^ *time_us = / { sub(/^ *time_us = */, ""); printf "%.6f", $0 / 1e6; exit }' "$W/state_after_kill.toml"
}
for node in 1 2 3; do
  before=$(frame_of "40$node" 0 "$t_kills" last); after=$(frame_of "40$node" "$t_last" 9999999999 first)
  [ -n "$before" ] && [ -n "$after" ] || fail "no GW_TEMPS_A of pump$node before the kills or after the last restart"
  b=$(degC "${before% *}" 1); a=$(degC "${after% *}" 1); f=$(saved_frame "pump$node"); ts=$(saved_time_s "pump$node")
  [ "$a" != n/a ] && [ "$b" != n/a ] || fail "pump$node: not available before ($b) or after ($a): a cold start?"
  [ -n "$f" ] && [ -n "$ts" ] || fail "pump$node: no x_degC or time_us in the restored state.toml"
  # The drift rate over the kills and the allowance it gives over this restart's gap.
  read -r rate gap allow <<EOF_ALLOW
$(awk -v a="$f" -v b="$b" -v ta="$ts" -v tb="${before#* }" -v tf="${after#* }" 'BEGIN {
    r = (ta > tb) ? (a - b) / (ta - tb) : 0; if (r < 0) r = -r; g = tf - ta
    printf "%.4f %.1f %.2f\n", r, g, 0.25 + 1.5 * r * (g > 0 ? g : 0) }')
EOF_ALLOW
  say "5. pump$node frame temperature: in the restored state.toml $f degC, first sent after the last restart $a degC, $gap s after the save (drift over the kills $rate K/s, allowed $allow K; sent before the kills $b degC)"
  awk -v a="$a" -v b="$f" -v k="$allow" 'BEGIN { d = a - b; if (d < 0) d = -d; exit !(d <= k) }' ||
    fail "pump$node: first frame temperature after the restart $a degC is more than $allow K (the drift over $gap s) from the restored $f degC"
  awk -v a="$a" -v b="$b" 'BEGIN { d = a - b; if (d < 0) d = -d; exit !(d <= 5.0) }' ||
    fail "pump$node: first frame temperature after the restart $a degC is more than 5 K from $b degC before the kills"
done

# GW_HEALTH.BusState (bits 52-53) went to passive (1) after the RX-passive error frame and back
# to active (0) after the active one.
bus_state_between() {  # the BusState values of GW_HEALTH of pump1 (0x601) between two times
  awk -v a="$1" -v b="$2" 'BEGIN { for (i = 0; i < 16; i++) h[sprintf("%X", i)] = i }
    { t = substr($1, 2, length($1) - 2) + 0; split($3, f, "#") }
    f[1] == "601" && t > a && t < b { print int(h[toupper(substr(f[2], 13, 1))] % 4) }' "$W/cap.log" | sort -u | tr '\n' ' '
}
passive=$(bus_state_between "$t_passive" "$t_active"); active=$(bus_state_between "$(awk -v t="$t_active" 'BEGIN { printf "%.6f", t + 1.5 }')" "$t_route_add")
say "2. GW_HEALTH.BusState of pump1 between the passive and the active error frame: $passive; after: $active"
echo "$passive" | grep -q '1' || fail "BusState never passive (1) after the RX-passive error frame"
[ "$active" = "0 " ] || fail "BusState '$active' after the active error frame, want 0 only"

# Every temperature sent: "not available" exactly where the offline run has none, else within
# 5 K of the offline run's range for that pump and signal.
awk "$decode_temps"'
  function emit(t, pump, sig, raw) {
    key = pump " " sig; n++
    if (!(key in lo)) { print "unexpected signal " key; bad++; return }
    if (raw == 65535) { na++; return }
    v = raw * 0.01 - 50
    if (lo[key] == "na") { printf "t=%.3f pump%d signal %d: %.2f degC where the offline run has none\n", t, pump, sig, v; bad++; return }
    d = (v < lo[key]) ? lo[key] - v : (v > hi[key] ? v - hi[key] : 0)
    if (d > worst) worst = d
    if (d > 5.0) { printf "t=%.3f pump%d signal %d: %.2f degC outside %.2f..%.2f by %.2f K\n", t, pump, sig, v, lo[key], hi[key], d; bad++ }
    ok++
  }
  FNR == NR { lo[$1 " " $2] = $3; hi[$1 " " $2] = $4; next }
  END { printf "SUMMARY %d values: %d temperatures, %d not available, %d bad; worst excursion %.2f K\n", n, ok, na, bad, worst; exit bad > 0 }
' "$W/envelope.txt" "$W/cap.log" >"$W/temps_check.txt" || { head -n 20 "$W/temps_check.txt"; fail "garbage temperatures on the bus"; }
say "throughout: $(wc -l <"$W/cap.log") frames captured; $(grep SUMMARY "$W/temps_check.txt" | sed 's/SUMMARY //')"
echo "$T: PASS ($(awk -v a="$t_start" -v b="$(date +%s.%N)" 'BEGIN { printf "%.0f", b - a }') s)"
