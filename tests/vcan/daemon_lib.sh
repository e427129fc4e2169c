# Shared helpers for the daemon's vcan scenarios (sourced; POSIX sh).

fail() {
  echo "$SCENARIO_NAME: FAIL: $*"
  for f in "$WORK_DIR"/daemon.err "$WORK_DIR"/daemon.out; do
    [ -f "$f" ] && { echo "--- $f"; sed 's/^/  /' "$f"; }
  done
  exit 1
}

# start_daemon CONFIG [ENV=VALUE...]: starts pumpthermd in the background and waits until it
# says it is listening (its sockets are bound).
start_daemon() {
  cfg=$1
  shift
  env "$@" "$BIN_DIR/pumpthermd" --config "$cfg" >"$WORK_DIR/daemon.out" 2>"$WORK_DIR/daemon.err" &
  DAEMON_PID=$!
  tries=0
  # The background shell may not have opened daemon.err yet: no complaint from grep then.
  until grep -q "listening on" "$WORK_DIR/daemon.err" 2>/dev/null; do
    tries=$((tries + 1))
    [ "$tries" -le 100 ] || fail "pumpthermd did not start listening within 20 s"
    kill -0 "$DAEMON_PID" 2>/dev/null || fail "pumpthermd exited at start"
    sleep 0.2
  done
}

# stop_daemon: SIGTERM, wait, and require a clean exit (status 0).
stop_daemon() {
  kill -0 "$DAEMON_PID" 2>/dev/null || fail "pumpthermd died before it was stopped"
  kill -TERM "$DAEMON_PID"
  rc=0
  wait "$DAEMON_PID" || rc=$?
  [ "$rc" -eq 0 ] || fail "pumpthermd exited with $rc on SIGTERM"
}

# count_of ID: the daemon's final frame count for CAN ID (as printed, e.g. 181) on vcan0.
count_of() {
  awk -v id="$1" '$1 == "vcan0" && $2 == id { print $3; found = 1 } END { if (!found) print 0 }' \
    "$WORK_DIR/daemon.out"
}
