#!/bin/sh
# pumptherm-spy under Xvfb, fed by pumptherm-lcm-demo, both inside a network namespace made
# here (multicast on its loopback only, ttl=0: nothing leaves the namespace).
#
#   spy_screenshot.sh BUILD_DIR [OUT.png]   screenshot of the spy with decoded messages open
#                                           (default docs/img/pumptherm-spy.png)
#   spy_screenshot.sh --lcm-log FILE BUILD_DIR [OUT.png]
#                                           the same fed by lcm-logplayer playing FILE at 20x
#                                           (the demo's gateway.lcm: pumps pump1..3; the views
#                                           of pump3), the screenshot at its end
#   spy_screenshot.sh --check BUILD_DIR     smoke test: the spy finds every type of
#                                           protocol/lcm and opens a view per type (a
#                                           double click: the pumptherm view of ours),
#                                           and the pumptherm view of a TEMPS and an ALARM
#                                           channel names their statuses
#
# Needs root (ip netns), Xvfb, xdotool, java; for the screenshot also xwd (x11-apps) and
# ImageMagick's convert. Exits 77 (skip) when something is missing, 1 on failure.
set -eu

mode=shot
lcm_log=""
if [ "${1:-}" = "--check" ]; then
  mode=check
  shift
fi
if [ "${1:-}" = "--lcm-log" ]; then
  lcm_log=$(CDPATH= cd -- "$(dirname -- "$2")" && pwd)/$(basename -- "$2")
  shift 2
fi
if [ $# -lt 1 ]; then
  echo "usage: $0 [--check] [--lcm-log FILE] BUILD_DIR [OUT.png]" >&2
  exit 2
fi
source_dir=$(CDPATH= cd -- "$(dirname -- "$0")/../.." && pwd)
build_dir=$(CDPATH= cd -- "$1" && pwd)
out=${2:-$source_dir/docs/img/pumptherm-spy.png}

work=""
skip() {
  echo "SKIP: $*"
  exit 77
}
failed=""
# Prints FAIL and the logs of the spy and of Xvfb, without exiting.
report() {
  failed=1
  echo "FAIL: $*" >&2
  if [ -n "$work" ]; then
    [ -f "$work/spy.log" ] && sed 's/^/  spy: /' "$work/spy.log" >&2
    [ -s "$work/xvfb.log" ] && sed 's/^/  Xvfb: /' "$work/xvfb.log" >&2
  fi
  return 0
}
fail() {
  report "$@"
  exit 1
}

[ "$(id -u)" = 0 ] || skip "needs root to create a network namespace (ip netns)"
tools="ip Xvfb xdotool java"
[ "$mode" = shot ] && tools="$tools xwd convert"
for tool in $tools; do
  command -v "$tool" > /dev/null 2>&1 || skip "$tool is not installed (packages: iproute2 xvfb xdotool default-jre x11-apps imagemagick)"
done
spy=$build_dir/tools/pumptherm-spy
demo=$build_dir/tools/pumptherm-lcm-demo
[ -x "$spy" ] && [ -x "$demo" ] || fail "build $spy and $demo first (targets pumptherm_lcm_demo, pumptherm_lcm_types_jar, pumptherm_spy_plugin_jar)"

work=$(mktemp -d /tmp/pumptherm-spy.XXXXXX)
ns=pumptherm-spy-$$
pids=""
cleanup() {
  status=$?
  if [ "$status" -ne 0 ] && [ "$status" -ne 77 ] && [ -z "$failed" ]; then
    report "a step failed (exit $status); see the messages above"
  fi
  for pid in $pids; do
    kill "$pid" 2> /dev/null || true
  done
  for pid in $pids; do
    wait "$pid" 2> /dev/null || true
  done
  ip netns del "$ns" 2> /dev/null || true
  rm -rf "$work"
}
trap cleanup EXIT
trap 'exit 1' INT TERM

ip netns add "$ns" 2> "$work/netns.log" || skip "cannot create a network namespace: $(cat "$work/netns.log")"
in_ns() { ip netns exec "$ns" "$@"; }
in_ns ip link set lo up
in_ns ip link set lo multicast on
in_ns ip route add 224.0.0.0/4 dev lo
url='udpm://239.255.76.67:7667?ttl=0'

# Background processes are started by `ip netns exec` itself (not through in_ns), so that $!
# is the process (ip execs the command) and cleanup can kill it.
# Xvfb picks a free display and writes its number to the file.
ip netns exec "$ns" Xvfb -displayfd 1 -screen 0 1920x1200x24 -nolisten tcp > "$work/display" 2> "$work/xvfb.log" &
pids="$! $pids"
for _ in $(seq 100); do
  [ -s "$work/display" ] && break
  sleep 0.2
done
[ -s "$work/display" ] || fail "Xvfb did not start: $(cat "$work/xvfb.log")"
DISPLAY=:$(head -n 1 "$work/display")
export DISPLAY

ip netns exec "$ns" "$spy" --lcm-url="$url" > "$work/spy.log" 2>&1 &
pids="$! $pids"

# X clients run in the namespace too: the X server's abstract socket is only reachable there,
# and a client outside could reach another display of the same number through its own.
xdo() { ip netns exec "$ns" xdotool "$@"; }

# Polls until `xdotool search --name PATTERN` finds a window, at most TRIES (300) times 0.2 s;
# prints its id.
wait_window() {
  for _ in $(seq "${2:-300}"); do
    id=$(xdo search --name "$1" 2> /dev/null | head -n 1) || true
    if [ -n "$id" ]; then
      echo "$id"
      return 0
    fi
    sleep 0.2
  done
  return 1
}

main=$(wait_window '^LCM Spy$') || fail "lcm-spy's window did not appear"
types=$(ls "$source_dir"/protocol/lcm/*.lcm | wc -l)
for _ in $(seq 50); do
  grep -q "Found $types LCM types" "$work/spy.log" && break
  sleep 0.2
done
grep -q "Found $types LCM types" "$work/spy.log" || fail "lcm-spy did not find the $types pumptherm types"

if [ -n "$lcm_log" ]; then
  # The demo's LCM log at 20x: the first second of it brings every channel.
  ip netns exec "$ns" lcm-logplayer --speed=20 -l "$url" "$lcm_log" > "$work/demo.log" 2>&1 &
  player=$!
  pids="$player $pids"
  channels="PUMPTHERM/GATEWAY/HEALTH
PUMPTHERM/pump1/ALARM
PUMPTHERM/pump1/TELEMETRY
PUMPTHERM/pump1/TEMPS
PUMPTHERM/pump2/ALARM
PUMPTHERM/pump2/TELEMETRY
PUMPTHERM/pump2/TEMPS
PUMPTHERM/pump3/ALARM
PUMPTHERM/pump3/TELEMETRY
PUMPTHERM/pump3/TEMPS"
  views="PUMPTHERM/pump3/TEMPS PUMPTHERM/pump3/ALARM PUMPTHERM/pump3/TELEMETRY"
else
# The publisher starts once the spy listens: its first tick carries every channel (the clear
# command included), so all nine rows are there from the start and stay in place.
ip netns exec "$ns" "$demo" --url "$url" --pumps tmp1,tmp2 --clear-period-s 2 \
  --duration-s 600 > "$work/demo.log" 2>&1 &
pids="$! $pids"
views="PUMPTHERM/tmp2/TEMPS PUMPTHERM/tmp2/ALARM PUMPTHERM/tmp1/TELEMETRY"

# The spy lists channels sorted by name, one table row each.
channels="PUMPTHERM/GATEWAY/HEALTH
PUMPTHERM/tmp1/ALARM
PUMPTHERM/tmp1/ALARM_CLEAR
PUMPTHERM/tmp1/TELEMETRY
PUMPTHERM/tmp1/TEMPS
PUMPTHERM/tmp2/ALARM
PUMPTHERM/tmp2/ALARM_CLEAR
PUMPTHERM/tmp2/TELEMETRY
PUMPTHERM/tmp2/TEMPS"
fi
sleep 4
xdo windowmove "$main" 0 0 windowsize "$main" 940 240
sleep 1

# Opens the view of CHANNEL (double click on its row) and places it at X Y W H.
row_top_px=19  # height of the table header
row_px=16      # height of a row
open_view() {
  channel=$1
  row=$(printf '%s\n' "$channels" | grep -n -x "$channel" | cut -d: -f1)
  y=$((row_top_px + row_px * (row - 1) + row_px / 2))
  # A busy machine can lose a click: try again while no view has opened. A view of another
  # channel (a click that hit the wrong row) would open over the table: move it aside.
  view=""
  for _ in 1 2 3 4 5 6 7 8 9 10; do
    # Java may place a new view itself after we moved it: keep the table on top for the click.
    xdo windowraise "$main"
    sleep 0.3
    xdo mousemove 90 "$y" click --repeat 2 --delay 100 1
    # A double click opens the pumptherm view of the pumptherm types (its title becomes
    # "CHANNEL: summary" once a message is shown), lcm-spy's structure view of the others.
    view=$(wait_window "^$channel(: .*)?\$" 25) && break
    for stray in $(xdo search --name '^PUMPTHERM/' 2> /dev/null); do
      case " $placed " in
        *" $stray "*) ;;
        *) xdo windowmove "$stray" 1300 1000 ;;
      esac
    done
  done
  if [ -z "$view" ]; then
    for w in $(xdo search --name . 2> /dev/null); do
      echo "  window: $(xdo getwindowname "$w")" >&2
    done
    fail "no decoded view opened for $channel after 10 double clicks"
  fi
  placed="$placed $view"
  layout="$layout$view $2 $3 $4 $5
"
  apply_layout
}
# Moves every placed view to its place and waits until the X server reports it there (Java
# may move a window it has just shown once more).
apply_layout() {
  printf '%s' "$layout" | while read -r id x y w h; do
    for _ in $(seq 25); do
      xdo windowmove "$id" "$x" "$y" windowsize "$id" "$w" "$h"
      sleep 0.2
      xdo getwindowgeometry "$id" | grep -q "Position: $x,$y " && break
    done
  done
}
placed=""
layout=""
set -- $views
open_view "$1" 945 0 975 640
open_view "$2" 0 245 940 470
open_view "$3" 945 645 975 555
open_view PUMPTHERM/GATEWAY/HEALTH 0 720 940 480
sleep 3
xdo windowraise "$main"
apply_layout
sleep 1

# The pumptherm view (tools/spy's plugin): a right click on the channel's row opens lcm-spy's
# "Viewers" menu, its second entry is the plugin's. The plugin puts a summary of the message it
# decoded (statuses by name) in its window's title, which is what this test can read.
open_plugin() {
  channel=$1
  row=$(printf '%s\n' "$channels" | grep -n -x "$channel" | cut -d: -f1)
  y=$((row_top_px + row_px * (row - 1) + row_px / 2))
  view=""
  for _ in 1 2 3 4 5; do
    xdo windowraise "$main"
    sleep 0.3
    xdo mousemove 90 "$y" click 3
    sleep 0.7
    xdo key Down Down Return
    view=$(wait_window "^$channel: $2\$" 50) && break
    xdo key Escape
  done
  if [ -z "$view" ]; then
    for w in $(xdo search --name . 2> /dev/null); do
      echo "  window: $(xdo getwindowname "$w")" >&2
    done
    fail "no pumptherm view of $channel showing '$2'"
  fi
  echo "pumptherm view: $(xdo getwindowname "$view")"
  xdo windowmove "$view" 1300 700
}
if [ "$mode" = check ]; then
  open_plugin PUMPTHERM/tmp1/TEMPS 'pump tmp1, [0-9]+ nodes, filter (not started|converging|tracking|rejecting|fault), alarm (normal|warning|trip)( \(.*\))?'
  open_plugin PUMPTHERM/tmp2/ALARM 'pump tmp2, alarm warning, conditions: rate of rise'
  sleep 1
fi

if grep -q -i -E "exception|error" "$work/spy.log"; then
  fail "lcm-spy reported errors"
fi
if [ "$mode" = check ]; then
  echo "pumptherm-spy found $types types, opened decoded views of 4 channels and 2 pumptherm views"
  exit 0
fi
if [ -n "$lcm_log" ]; then
  wait "$player" 2> /dev/null || true  # the log's end: pump3 tripped
  sleep 1.5
fi
mkdir -p "$(dirname "$out")"
ip netns exec "$ns" xwd -root -silent | convert xwd:- "png:$out"
echo "wrote $out"
