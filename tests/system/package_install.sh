#!/bin/sh
# System test: the project's .deb installed with apt in a fresh Debian 12
# guest (no network), then the service from the package, as docs/operator-guide.md tells an
# operator: nothing runs until /etc/pumptherm/pumpthermd.toml exists; with the demo
# configuration on vcan0 it starts, a recording made by the packaged `pumptherm plant` is
# replayed with canplayer, and the gateway's temperature frames, decoded with the packaged DBC,
# follow the recording's truth. Then remove keeps the configuration and state; purge deletes
# them. Runs as root in the guest (tests/system/run_system_test.sh); vcan0 is up; the .deb is
# in $DATA_DIR.
set -eu
T=package_install
unit=pumpthermd.service
replay_s=${PUMPTHERM_REPLAY_S:-40}

show() { systemctl show -p "$1" --value "$unit"; }
fail() {
  echo "$T: FAIL: $*"
  echo "--- systemctl status $unit"
  systemctl status --no-pager --full "$unit" 2>&1 | sed 's/^/  /' || true
  echo "--- journalctl -u $unit (last 40 lines)"
  journalctl -u "$unit" --no-pager -o short-monotonic 2>&1 | tail -n 40 | sed 's/^/  /' || true
  exit 1
}
wait_for() {  # wait_for SECONDS COMMAND...
  limit=$(($1 * 5)); shift
  n=0
  until "$@"; do
    n=$((n + 1))
    [ "$n" -le "$limit" ] || return 1
    sleep 0.2
  done
}
uptime_s() { cut -d' ' -f1 /proc/uptime; }
since() { awk -v a="$1" -v b="$(uptime_s)" 'BEGIN { printf "%.1f", b - a }'; }

# 1. apt install ./pumptherm_*.deb (the daemon) alone, offline: a gateway host needs no tools;
#    then ./pumptherm-tools_*.deb, which this test uses to make its recording.
deb=$(ls "$DATA_DIR"/pumptherm_*.deb | head -n 1)
tools_deb=$(ls "$DATA_DIR"/pumptherm-tools_*.deb | head -n 1)
[ -n "$deb" ] || fail "no pumptherm_*.deb in $DATA_DIR"
[ -n "$tools_deb" ] || fail "no pumptherm-tools_*.deb in $DATA_DIR"
cp "$deb" "$tools_deb" "$WORK_DIR/"
deb=$WORK_DIR/$(basename "$deb")
tools_deb=$WORK_DIR/$(basename "$tools_deb")
t0=$(uptime_s)
timeout 300 apt-get install -y --no-install-recommends "$deb" >"$WORK_DIR/apt.log" 2>&1 ||
  { sed 's/^/  /' "$WORK_DIR/apt.log"; fail "apt-get install $deb"; }
sed 's/^/  /' "$WORK_DIR/apt.log" | tail -n 6
echo "$T: apt-get install $(basename "$deb") took $(since "$t0") s (guest time, TCG)"
dpkg-query -W -f='${Status} ${Version}\n' pumptherm | grep -q '^install ok installed ' ||
  fail "dpkg says: $(dpkg-query -W -f='${Status}' pumptherm)"
for f in /usr/sbin/pumpthermd /lib/systemd/system/$unit /etc/pumptherm/pumpthermd.toml.example \
         /usr/share/man/man8/pumpthermd.8.gz /usr/share/doc/pumptherm/operator-guide.md; do
  [ -e "$f" ] || fail "$f is not installed"
done
[ ! -e /usr/bin/pumptherm ] || fail "the daemon's package installed /usr/bin/pumptherm (a tool)"
echo "$T: the daemon's package alone: pumpthermd and its unit, no tools"
timeout 300 apt-get install -y --no-install-recommends "$tools_deb" >"$WORK_DIR/apt-tools.log" 2>&1 ||
  { sed 's/^/  /' "$WORK_DIR/apt-tools.log"; fail "apt-get install $tools_deb"; }
for f in /usr/bin/pumptherm /usr/bin/pumptherm-spy /usr/share/man/man1/pumptherm.1.gz; do
  [ -e "$f" ] || fail "$f is not installed by pumptherm-tools"
done
pumpthermd --version | sed "s/^/$T: /"

# 2. Installed, enabled, but nothing runs: there is no configuration yet.
[ "$(systemctl is-enabled $unit)" = enabled ] || fail "unit is $(systemctl is-enabled $unit), want enabled"
[ "$(show ActiveState)" = inactive ] || fail "running right after install: $(show ActiveState)"
[ "$(show ConditionResult)" = no ] || fail "ConditionResult=$(show ConditionResult), want no (postinst's start skipped)"
[ ! -e /etc/pumptherm/pumpthermd.toml ] || fail "the package created /etc/pumptherm/pumpthermd.toml"
echo "$T: installed and enabled; not started (no /etc/pumptherm/pumpthermd.toml)"

# 3. The operator's configuration: the shipped demo configuration on vcan0.
sed 's/^interface = "can0"/interface = "vcan0"/' /usr/share/pumptherm/examples/pumpthermd-demo.toml \
  >/etc/pumptherm/pumpthermd.toml
pumpthermd --check-config /etc/pumptherm/pumpthermd.toml | sed "s/^/$T: /" ||
  fail "pumpthermd --check-config rejects the demo configuration"

# 4. A recording from the packaged simulator (shipped scenario), cut to $replay_s s.
t0=$(uptime_s)
pumptherm plant demo --duration-s "$replay_s" --quiet --out "$WORK_DIR/demo" ||
  fail "pumptherm plant demo (packaged scenario)"
echo "$T: pumptherm plant demo --duration-s $replay_s: $(wc -l <"$WORK_DIR/demo/demo.log") frames in $(since "$t0") s"

# 5. Start the service, replay the recording in real time onto vcan0, capture the output.
t0=$(uptime_s)
systemctl start "$unit" || fail "systemctl start"
echo "$T: systemctl start returned after $(since "$t0") s"
[ "$(show ActiveState)/$(show SubState)" = active/running ] || fail "not running after start"
timeout $((replay_s + 30)) candump -L vcan0,400:7C0 >"$WORK_DIR/out.log" 2>&1 &
candump_pid=$!
sleep 0.5
canplayer -I "$WORK_DIR/demo/demo.log" vcan0=can0 || fail "canplayer"
sleep 3
kill "$candump_pid" 2>/dev/null || true
wait "$candump_pid" 2>/dev/null || true
status=$(show StatusText)
echo "$T: StatusText=$status"
echo "$status" | grep -q '3 pumps' || fail "StatusText does not report 3 pumps"
journalctl -u "$unit" --no-pager -o cat | tail -n 8 | sed 's/^/  journal: /'

# 6. Temperatures on CAN, decoded with the packaged DBC: every pump, finite, and the frame node
# (the measured one) within 3 K of the simulator's truth at the end of the recording.
pumptherm dbc decode --dbc /usr/share/pumptherm/dbc/pumptherm.dbc --node-id-limit 16 \
  --message GW_TEMPS_A --format csv "$WORK_DIR/out.log" >"$WORK_DIR/temps.csv" ||
  fail "pumptherm dbc decode of the captured output"
head -n 1 "$WORK_DIR/temps.csv" | sed "s/^/$T: decoded columns: /"
cp "$WORK_DIR/temps.csv" "$WORK_DIR/out.log" "$OUT_DIR/" 2>/dev/null || true
for n in 1 2 3; do
  # The last GW_TEMPS_A of node n with a number in Frame_degC.
  est=$(awk -F, -v n="$n" 'NR == 1 { for (i = 1; i <= NF; i++) c[$i] = i; next }
        $c["node"] == n && $c["GW_TEMPS_A.Frame_degC"] != "" { v = $c["GW_TEMPS_A.Frame_degC"] } END { print v }' "$WORK_DIR/temps.csv")
  truth=$(awk -F, 'NR == 1 { for (i = 1; i <= NF; i++) c[$i] = i; next } { v = $c[("frame_degC" in c) ? "frame_degC" : "frame_C"] } END { print v }' \
          "$WORK_DIR/demo/pump$n.truth.csv")
  [ -n "$est" ] || fail "no Frame_degC for pump node $n in the gateway's output"
  echo "$T: pump$n: frame estimated $est degC on CAN, truth $truth degC"
  awk -v e="$est" -v t="$truth" 'BEGIN { d = e - t; if (d < 0) d = -d; exit !(d <= 3) }' ||
    fail "pump$n: frame estimate $est degC is more than 3 K from the truth $truth degC"
done

# 7. Stop: the state is saved in the unit's StateDirectory.
systemctl stop "$unit" || fail "systemctl stop"
[ "$(show Result)" = success ] || fail "Result=$(show Result) after stop"
[ -s /var/lib/pumptherm/state.toml ] || fail "no /var/lib/pumptherm/state.toml after stop"
echo "$T: stopped; state saved in /var/lib/pumptherm/state.toml"

# 8. remove keeps the operator's configuration and the state; purge deletes them.
apt-get remove -y pumptherm >"$WORK_DIR/remove.log" 2>&1 || { cat "$WORK_DIR/remove.log"; fail "apt-get remove"; }
[ ! -e /usr/sbin/pumpthermd ] || fail "remove left /usr/sbin/pumpthermd"
[ -f /etc/pumptherm/pumpthermd.toml ] || fail "remove deleted /etc/pumptherm/pumpthermd.toml"
[ -s /var/lib/pumptherm/state.toml ] || fail "remove deleted the state"
echo "$T: removed; configuration and state kept"
apt-get purge -y pumptherm >"$WORK_DIR/purge.log" 2>&1 || { cat "$WORK_DIR/purge.log"; fail "apt-get purge"; }
[ ! -e /etc/pumptherm ] || fail "purge left /etc/pumptherm: $(ls -A /etc/pumptherm)"
[ ! -e /var/lib/pumptherm ] && [ ! -e /var/lib/private/pumptherm ] || fail "purge left the state"
dpkg-query -W -f='${Status}\n' pumptherm 2>/dev/null | grep -q 'installed' &&
  fail "dpkg still lists pumptherm as installed after purge"
[ ! -e /etc/systemd/system/multi-user.target.wants/$unit ] || fail "purge left the enablement link"
echo "$T: purged; configuration, state and enablement gone"
echo "$T: PASS"
