# shellcheck shell=bash
# expect CODE PATTERN -- command...: runs the command, and passes when it exits with CODE and a
# line of its output (stdout and stderr) matches the extended regular expression PATTERN;
# otherwise prints the command, its exit code and output, and sets fail=1. For the CLI tests
# (sourced; bash).
expect() {
  local code=$1 pattern=$2
  shift 3
  local out rc
  out=$("$@" 2>&1)
  rc=$?
  if [[ $rc -ne $code ]] || ! grep -qE -- "$pattern" <<<"$out"; then
    echo "FAIL: $* -> exit $rc (want $code), output:"; echo "$out" | sed 's/^/    /'
    echo "    wanted a line matching: $pattern"
    fail=1
  else
    echo "ok: $* -> exit $rc: $(head -n1 <<<"$out")"
  fi
}
