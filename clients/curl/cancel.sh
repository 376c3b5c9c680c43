#!/usr/bin/env bash
# Cancels a queued or running job and prints its state.
set -euo pipefail
usage() { echo "usage: $(basename "$0") JOB_ID   (TESSERA_URL, default http://127.0.0.1:8080; TESSERA_TOKEN)"; }
if [[ ${1:-} == -h || ${1:-} == --help ]]; then usage; exit 0; fi
if [[ $# -ne 1 ]]; then usage >&2; exit 2; fi
source "$(dirname "$0")/common.sh"
job=$(request POST "/v1/jobs/$1/cancel")
json_field state <<<"$job"
