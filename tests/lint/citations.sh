#!/usr/bin/env bash
# Public text (API descriptions, docs, comments, messages) cites what a reader can find: a book with its section or a
# paper with its year, never the project's private notes ("seed 000") or its issue numbers ("issue 27").
# usage: citations.sh [REPO]     (run by CTest)
set -uo pipefail
repo=${1:-$(cd "$(dirname "$0")/../.." && pwd)}
cd "$repo" || exit 1
git rev-parse --is-inside-work-tree >/dev/null 2>&1 || { echo "not a git checkout: skipped"; exit 77; }
# This file names the patterns it looks for.
if found=$(git grep -nIiE '\bseed 0[0-9]{2}\b|\bseed notes\b|\bissues? #?[0-9]+\b' -- . ':!tests/lint/citations.sh'); then
  echo "$found"
  echo "cite the published source instead (book and section, paper and year)"
  exit 1
fi
echo "no private notes or issue numbers cited"
