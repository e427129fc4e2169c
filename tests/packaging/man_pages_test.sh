#!/usr/bin/env bash
# The man pages list exactly the options the binaries accept: for pumpthermd(8) the OPTIONS
# section against `pumpthermd --help`; for pumptherm(1) one subsection per subcommand (and per
# sub-subcommand, e.g. "pumptherm dbc check") against `pumptherm <sub> [<subsub>] --help`, and
# no subsection for a subcommand that does not exist. -h/--help is left out of the comparison
# (every command has it; the pages say so once). Also runs `man` on each page when it is
# installed, so that a roff error shows.
#   man_pages_test.sh PUMPTHERMD PUMPTHERM MAN_DIR
set -u
pumpthermd=$1
pumptherm=$2
man_dir=$3
fail=0
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

# Options in CLI11's --help: the first word of each line of the "Options:" block, split at ','.
help_options() {
  awk '/^$/ { in_opts = 0 } /^[A-Za-z].*:$/ { in_opts = ($0 == "Options:"); next }
       in_opts && /^  -/ { n = split($1, a, ","); for (i = 1; i <= n; i++) print a[i] }' |
    grep -vxE -- '-h|--help' | sort -u
}
# Subcommand names in CLI11's --help ("Subcommands:" block).
help_subcommands() {
  awk '/^$/ { in_subs = 0 } /^[A-Za-z].*:$/ { in_subs = ($0 == "Subcommands:"); next }
       in_subs && /^  [a-z]/ { print $1 }' | sort -u
}
# Options in a man page fragment: the words starting with '-' on the line after each .TP. Not
# made unique: an option described twice shows as a difference from --help.
man_options() {
  sed -e 's/\\-/-/g' -e 's/\\f[BIRP]//g' -e 's/"/ /g' -e 's/,/ /g' |
    awk 'prev_tp { for (i = 1; i <= NF; i++) if ($i ~ /^--?[A-Za-z0-9][-A-Za-z0-9]*$/) print $i }
         { prev_tp = ($1 == ".TP") }' |
    grep -vxE -- '-h|--help' | sort
}
# Lines of man page $1 in section .SH $2 (up to the next .SH).
man_section() {
  awk -v want="$2" '/^\.SH / { s = $0; sub(/^\.SH +/, "", s); gsub(/"/, "", s); on = (s == want); next }
                    on' "$1"
}
# Lines of man page $1 in subsection .SS $2 (up to the next .SS or .SH).
man_subsection() {
  awk -v want="$2" '/^\.S[SH] / { s = $0; sub(/^\.S[SH] +/, "", s); gsub(/"/, "", s); on = ($0 ~ /^\.SS/ && s == want); next }
                    on' "$1"
}
compare() {  # compare WHAT HELP_FILE MAN_FILE
  if [[ ! -s $3 ]]; then
    echo "FAIL: $1: the man page lists no options (help has: $(tr '\n' ' ' < "$2"))"
    fail=1
  elif diff -u --label "$1 --help" --label "$1 man page" "$2" "$3" > "$tmp/diff"; then
    echo "ok: $1: $(wc -l < "$2") options, the same in --help and the man page"
  else
    echo "FAIL: $1: options differ between --help (-) and the man page (+):"
    sed 's/^/    /' "$tmp/diff"
    fail=1
  fi
}

for page in pumpthermd.8 pumptherm.1 pumpthermd.toml.5 pumptherm-spy.1 pumptherm-lcm-demo.1; do
  [[ -f $man_dir/$page ]] || { echo "FAIL: $man_dir/$page is missing"; fail=1; }
done

# pumpthermd(8)
"$pumpthermd" --help | help_options > "$tmp/help"
man_section "$man_dir/pumpthermd.8" OPTIONS | man_options > "$tmp/man"
compare pumpthermd "$tmp/help" "$tmp/man"

# pumptherm(1): every subcommand (and sub-subcommand) has a subsection with its options.
"$pumptherm" --help | help_subcommands > "$tmp/subs"
[[ -s $tmp/subs ]] || { echo "FAIL: pumptherm --help lists no subcommands"; fail=1; }
commands=()
while read -r sub; do
  "$pumptherm" "$sub" --help > "$tmp/subhelp"
  help_subcommands < "$tmp/subhelp" > "$tmp/subsubs"
  if [[ -s $tmp/subsubs ]]; then
    while read -r subsub; do commands+=("$sub $subsub"); done < "$tmp/subsubs"
  else
    commands+=("$sub")
  fi
done < "$tmp/subs"
for c in "${commands[@]}"; do
  # shellcheck disable=SC2086  # word splitting of "dbc check" intended
  "$pumptherm" $c --help | help_options > "$tmp/help"
  man_subsection "$man_dir/pumptherm.1" "pumptherm $c" > "$tmp/section"
  if ! grep -q . "$tmp/section" && ! grep -qF ".SS \"pumptherm $c\"" "$man_dir/pumptherm.1"; then
    echo "FAIL: pumptherm.1 has no subsection .SS \"pumptherm $c\""
    fail=1
    continue
  fi
  man_options < "$tmp/section" > "$tmp/man"
  if [[ ! -s $tmp/help && ! -s $tmp/man ]]; then
    echo "ok: pumptherm $c: no options besides --help, none in the man page"
  else
    compare "pumptherm $c" "$tmp/help" "$tmp/man"
  fi
done
# No subsection for a command that does not exist.
printf 'pumptherm %s\n' "${commands[@]}" | sort > "$tmp/want_ss"
sed -n 's/^\.SS "\(pumptherm .*\)"$/\1/p' "$man_dir/pumptherm.1" | sort > "$tmp/have_ss"
if ! diff -u --label "subcommands (--help)" --label "subsections (pumptherm.1)" "$tmp/want_ss" "$tmp/have_ss"; then
  echo "FAIL: pumptherm.1's subsections differ from the subcommands"
  fail=1
else
  echo "ok: pumptherm.1 has one subsection per subcommand (${#commands[@]})"
fi

# pumptherm-spy(1) and pumptherm-lcm-demo(1): the lcm-demo binary sits beside pumptherm.
demo=$(dirname "$pumptherm")/pumptherm-lcm-demo
if [[ -x $demo ]]; then
  "$demo" --help | help_options > "$tmp/help"
  man_section "$man_dir/pumptherm-lcm-demo.1" OPTIONS | man_options > "$tmp/man"
  compare pumptherm-lcm-demo "$tmp/help" "$tmp/man"
else
  echo "FAIL: $demo not built"; fail=1
fi

# Each page formats without warnings (groff's own check), where man/groff are installed.
if command -v groff > /dev/null; then
  for page in "$man_dir"/*.[158]; do
    warnings=$(LC_ALL=C.UTF-8 groff -man -Tutf8 -ww -z "$page" 2>&1)
    if [[ -n $warnings ]]; then echo "FAIL: groff warns on $page:"; echo "$warnings" | sed 's/^/    /'; fail=1
    else echo "ok: groff formats $(basename "$page") without warnings"; fi
  done
else
  echo "note: groff not installed: formatting not checked"
fi
exit $fail
