#!/bin/bash
# Screenshot of `pumptherm watch` for docs/img/watch.txt: one line per pump, then one pump in
# full, captured from tmux (100 columns) while lcm-logplayer plays an LCM log of the gateway
# (the demo's: tools/demo.sh writes demo-out/gateway.lcm) at 20 times its pace, inside a network
# namespace made here (multicast on its loopback only). Not a test.
#   watch_screenshot.sh BUILD_DIR GATEWAY.lcm [OUT.txt [PUMP [AFTER_S]]]
# Needs root (ip netns), tmux, lcm-logplayer (liblcm-bin).
set -eu
build=$(cd "$1" && pwd)
log=$2
out=${3:-/dev/stdout}
pump=${4:-pump3}
after_s=${5:-50}
ns=pumptherm-watch-shot-$$
url='udpm://239.255.76.67:7667?ttl=0'
ip netns add "$ns"
trap 'tmux kill-session -t watch-table-$$ 2>/dev/null; tmux kill-session -t watch-pump-$$ 2>/dev/null; ip netns del "$ns" 2>/dev/null || true' EXIT
ip -n "$ns" link set lo up
ip -n "$ns" link set lo multicast on
ip -n "$ns" route add 224.0.0.0/4 dev lo
export TZ=${TZ:-UTC}
tmux new-session -d -s "watch-table-$$" -x 100 -y 12 \
  "ip netns exec $ns $build/tools/pumptherm watch --url '$url' --period-s 1; sleep 100"
tmux new-session -d -s "watch-pump-$$" -x 100 -y 40 \
  "ip netns exec $ns $build/tools/pumptherm watch $pump --url '$url' --period-s 1; sleep 100"
sleep 1
ip netns exec "$ns" lcm-logplayer --speed=20 -l "$url" "$log" &
player=$!
sleep "$after_s"
{
  echo "\$ pumptherm watch --url ...   ($(basename "$log") at 20x, $((after_s * 20 / 60)) min in)"
  tmux capture-pane -p -t "watch-table-$$" | sed -n '/^pump /,/^$/p' | tail -n 5
  echo
  echo "\$ pumptherm watch $pump --url ..."
  tmux capture-pane -p -t "watch-pump-$$" |
    awk -v p="$pump" 'index($0, p ": last message") == 1 { buf = "" } { buf = buf $0 "\n" } END { printf "%s", buf }'
} >"$out"
kill "$player" 2>/dev/null || true
wait "$player" 2>/dev/null || true
