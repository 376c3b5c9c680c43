#!/usr/bin/env bash
# Prints a job's progress until it ends; exits 0 when it succeeded, 1 otherwise.
set -euo pipefail
usage() { echo "usage: $(basename "$0") JOB_ID   (TESSERA_URL, default http://127.0.0.1:8080; WATCH_INTERVAL seconds, default 1)"; }
if [[ ${1:-} == -h || ${1:-} == --help ]]; then usage; exit 0; fi
if [[ $# -ne 1 ]]; then usage >&2; exit 2; fi
source "$(dirname "$0")/common.sh"
while true; do
  status=$(request GET "/v1/jobs/$1")
  line=$(python3 -c '
import json, sys
s = json.load(sys.stdin)
p = s["progress"]
eta = "?" if p["eta_s"] is None else "%.1fs" % p["eta_s"]
msg = "%-9s %3.0f%%  %d/%d spp  pass %d  %.1fs  eta %s  %.3g samples/s" % (
    s["state"], 100 * p["fraction"], p["samples_done"], p["samples_total"], p["passes"], p["elapsed_s"], eta,
    p["samples_per_s"])
if s.get("stop_reason"): msg += "  stopped by " + s["stop_reason"]
if s.get("error"): msg += "  error: " + s["error"]
print(s["state"] + "\t" + msg)
' <<<"$status")
  state=${line%%$'\t'*}
  echo "${line#*$'\t'}"
  case $state in
    succeeded) exit 0 ;;
    failed | cancelled) exit 1 ;;
  esac
  sleep "${WATCH_INTERVAL:-1}"
done
