#!/usr/bin/env bash
# Downloads a finished job's results (result.png, result.exr: those the job asked for) into DIR.
set -euo pipefail
usage() { echo "usage: $(basename "$0") JOB_ID DIR   (TESSERA_URL, default http://127.0.0.1:8080)"; }
if [[ ${1:-} == -h || ${1:-} == --help ]]; then usage; exit 0; fi
if [[ $# -ne 2 ]]; then usage >&2; exit 2; fi
source "$(dirname "$0")/common.sh"
mkdir -p "$2"
trap 'rm -f "$2"/.result.*.part' EXIT
job=$(request GET "/v1/jobs/$1")
outputs=$(python3 -c 'import json, sys; print(" ".join(json.load(sys.stdin)["outputs"]))' <<<"$job")
for ext in $outputs; do
  tmp="$2/.result.$ext.part"
  request GET "/v1/jobs/$1/result.$ext" >"$tmp"
  mv "$tmp" "$2/result.$ext"
  echo "$2/result.$ext"
done
