#!/usr/bin/env bash
# Every tracked .cpp and .h file is as clang-format (the repository's .clang-format) writes it: `make format` fixes
# what this finds. Without a git checkout (a source tarball) there is no list of tracked files: skipped (exit 77).
# usage: clang_format.sh [REPO]     (run by CTest)
set -uo pipefail
repo=${1:-$(cd "$(dirname "$0")/../.." && pwd)}
cd "$repo" || exit 1
command -v clang-format >/dev/null || { echo "clang-format is not installed (deploy/install-deps.sh test)"; exit 1; }
git rev-parse --is-inside-work-tree >/dev/null 2>&1 || { echo "not a git checkout: skipped"; exit 77; }
mapfile -t files < <(git ls-files '*.cpp' '*.h')
[[ ${#files[@]} -gt 0 ]] || { echo "no C++ files tracked"; exit 1; }
if ! out=$(clang-format --dry-run -Werror "${files[@]}" 2>&1); then
  grep -o '^[^:]*\.\(cpp\|h\):[0-9]*' <<<"$out" | sort -u -t: -k1,1 | sed 's/^/not formatted: /'
  echo "run \`make format\` (clang-format -i on the tracked files)"
  exit 1
fi
echo "${#files[@]} files formatted as .clang-format says"
