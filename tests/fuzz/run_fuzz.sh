#!/usr/bin/env bash
# Runs one libFuzzer target of tests/fuzz three ways:
#   run_fuzz.sh replay TARGET CORPUS            every file of CORPUS once (the regression test of its finds)
#   run_fuzz.sh runs TARGET CORPUS WORK N SEED  N executions from CORPUS with the fixed seed SEED (CTest: the same
#                                               inputs every run); WORK is emptied first and receives what it adds
#                                               to the corpus and any crash
#   run_fuzz.sh long TARGET CORPUS FINDINGS S   S seconds of fuzzing (`make fuzz`); new inputs go to
#                                               FINDINGS/corpus and crashes, timeouts and out-of-memory inputs to
#                                               FINDINGS/, never into the tree
# libFuzzer's options (https://llvm.org/docs/LibFuzzer.html#options): a directory given first is the one new inputs
# are written to, the later ones are only read.
set -euo pipefail
mode=$1 target=$2 corpus=$3
shift 3
# The target's own options, fuzz_<name>: <name>.options beside this script (comments start with #).
options=()
options_file="$(dirname "$0")/$(basename "$target" | sed 's/^fuzz_//').options"
if [[ -f $options_file ]]; then mapfile -t options < <(grep -v '^\s*\(#\|$\)' "$options_file"); fi
case "$mode" in
  replay)
    shopt -s nullglob
    files=("$corpus"/*)
    [[ ${#files[@]} -gt 0 ]] || { echo "no inputs in $corpus" >&2; exit 1; }
    exec "$target" "${options[@]}" -print_final_stats=1 "${files[@]}"
    ;;
  runs)
    work=$1 runs=$2 seed=$3
    rm -rf "$work"
    mkdir -p "$work/corpus"
    exec "$target" "${options[@]}" -runs="$runs" -seed="$seed" -print_final_stats=1 -artifact_prefix="$work/" \
      "$work/corpus" "$corpus"
    ;;
  long)
    findings=$1 seconds=$2
    mkdir -p "$findings/corpus"
    # -timeout: an input running 10 s is reported (a hang); the limits of the targets make a run milliseconds.
    exec "$target" "${options[@]}" -max_total_time="$seconds" -timeout=10 -print_final_stats=1 -artifact_prefix="$findings/" \
      "$findings/corpus" "$corpus"
    ;;
  *)
    echo "usage: run_fuzz.sh replay|runs|long TARGET CORPUS ..." >&2
    exit 2
    ;;
esac
