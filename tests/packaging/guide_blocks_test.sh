#!/usr/bin/env bash
# docs/operator-guide.md's code blocks, checked on the host in a second (the guest test
# system.operator_guide runs them): every ```sh block parses with `sh -n`; every ```sh norun
# block starts with a comment giving the reason it is not run; the guide has no other shell
# fences (```bash, ```shell) that the extractor would silently skip.
#   guide_blocks_test.sh GUIDE
set -u
guide=$1
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail=0
awk -v dir="$tmp" '
  /^```sh norun/ { n++; f = sprintf("%s/norun_%02d_%d.sh", dir, n, NR + 1); on = 1; next }
  /^```sh$/      { n++; f = sprintf("%s/run_%02d_%d.sh", dir, n, NR + 1); on = 1; next }
  /^```(bash|shell|console)/ { printf "line %d: %s\n", NR, $0 > (dir "/other") }
  /^```/         { on = 0; next }
  on             { print > f }' "$guide"
if [[ -s $tmp/other ]]; then echo "FAIL: shell fences the extractor does not run:"; cat "$tmp/other"; fail=1; fi
runs=0
for f in "$tmp"/run_*.sh; do
  runs=$((runs + 1))
  line=${f##*_}; line=${line%.sh}
  sh -n "$f" 2> "$tmp/err" || { echo "FAIL: block at guide line $line does not parse:"; cat "$tmp/err"; fail=1; }
done
for f in "$tmp"/norun_*.sh; do
  [[ -e $f ]] || continue
  line=${f##*_}; line=${line%.sh}
  head -n 1 "$f" | grep -q '^# ..*' || { echo "FAIL: norun block at guide line $line gives no reason (first line a comment)"; fail=1; }
done
echo "guide: $runs sh blocks parse; $(ls "$tmp"/norun_*.sh 2>/dev/null | wc -l) norun blocks with a reason"
exit $fail
