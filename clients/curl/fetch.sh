#!/usr/bin/env bash
# Downloads a finished job's results (result.png, result.exr: those the job asked for) into DIR; of a job cancelled
# after a pass, the image of that pass (partial results, said on stderr).
# Exits 1 when the job has no results: it failed or was cancelled before its first pass, or has not finished yet (the
# message says which).
set -euo pipefail
usage() { echo "usage: $(basename "$0") JOB_ID DIR   (TESSERA_URL, default http://127.0.0.1:8080; TESSERA_TOKEN)"; }
if [[ ${1:-} == -h || ${1:-} == --help ]]; then usage; exit 0; fi
if [[ $# -ne 2 ]]; then usage >&2; exit 2; fi
source "$(dirname "$0")/common.sh"
id=$1
dir=${2%/}
dir=${dir:-/}
job=$(request GET "/v1/jobs/$id")
state=$(json_field state <<<"$job")
case $state in
  succeeded | failed | cancelled) ;;
  *) echo "error: job $id is $state: results exist once it has succeeded (watch.sh $id waits for it)" >&2; exit 1 ;;
esac
# The status links the results there are: a succeeded job's outputs, and the image of the last complete pass of a job
# cancelled after one (its partial results).
exts=$(python3 -c 'import json, sys; j = json.load(sys.stdin); print(" ".join(o for o in j["outputs"] if "result_" + o in j["links"]))' <<<"$job")
if [[ -z $exts ]]; then echo "error: job $id $state: it has no results" >&2; exit 1; fi
if [[ $state != succeeded ]]; then
  done_spp=$(json_field progress.samples_done <<<"$job")
  total_spp=$(json_field progress.samples_total <<<"$job")
  echo "job $id $state: its results are a partial image of $done_spp of $total_spp samples per pixel" >&2
fi
mkdir -p "$dir"
trap 'rm -f "$dir"/.result.*.part' EXIT
for ext in $exts; do
  part="$dir/.result.$ext.part"
  request GET "/v1/jobs/$id/result.$ext" >"$part"
  mv "$part" "$dir/result.$ext"
  echo "$dir/result.$ext"
done
