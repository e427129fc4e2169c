#!/usr/bin/env bash
# Checks that every C++ source under version control is formatted as .clang-format says
# (Google style, 100 columns). Prints the files that differ and exits 1; `--fix` formats them.
# Needs clang-format 14 (Debian package clang-format); the style differs between major versions.
set -euo pipefail
cd "$(dirname "$0")/.."
command -v clang-format >/dev/null || { echo "$0: clang-format is not installed (tools/setup.sh installs it)" >&2; exit 2; }
mapfile -t files < <(git ls-files '*.cpp' '*.hpp' '*.h' '*.cc')
if [[ ${1:-} == --fix ]]; then
  clang-format -i --style=file "${files[@]}"
  exit 0
fi
bad=()
for f in "${files[@]}"; do
  clang-format --style=file --dry-run -Werror "$f" >/dev/null 2>&1 || bad+=("$f")
done
if ((${#bad[@]})); then
  printf '%s: %d of %d files are not formatted (tools/format-check.sh --fix formats them):\n' \
    "$0" "${#bad[@]}" "${#files[@]}" >&2
  printf '  %s\n' "${bad[@]}" >&2
  exit 1
fi
echo "format: ${#files[@]} files follow .clang-format"
