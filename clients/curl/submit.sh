#!/usr/bin/env bash
# Submits a job document to tesserad and prints the new job's id.
set -euo pipefail
usage() { echo "usage: $(basename "$0") JOB.json   (prints the job id; TESSERA_URL, default http://127.0.0.1:8080)"; }
if [[ ${1:-} == -h || ${1:-} == --help ]]; then usage; exit 0; fi
if [[ $# -ne 1 ]]; then usage >&2; exit 2; fi
[[ $1 == - || -r $1 ]] || { echo "error: cannot read $1" >&2; exit 2; }
source "$(dirname "$0")/common.sh"
job=$(request POST /v1/jobs -H 'Content-Type: application/json' --data-binary "@$1")
json_field id <<<"$job"
