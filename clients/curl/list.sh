#!/usr/bin/env bash
# Lists jobs, newest first: id, state, samples done/total, created. Optional STATE filters.
set -euo pipefail
usage() { echo "usage: $(basename "$0") [queued|running|succeeded|failed|cancelled]   (TESSERA_URL, default http://127.0.0.1:8080)"; }
if [[ ${1:-} == -h || ${1:-} == --help ]]; then usage; exit 0; fi
if [[ $# -gt 1 ]]; then usage >&2; exit 2; fi
source "$(dirname "$0")/common.sh"
query=""
if [[ $# -eq 1 ]]; then query="?state=$1"; fi
jobs=$(request GET "/v1/jobs$query")
python3 -c '
import json, sys
for j in json.load(sys.stdin)["jobs"]:
    p = j["progress"]
    print("%s  %-9s  %5d/%-5d spp  %s" % (j["id"], j["state"], p["samples_done"], p["samples_total"], j["created_at"]))
' <<<"$jobs"
