#!/usr/bin/env bash
# Prints a job's progress until it ends; exits 0 when it succeeded, 1 otherwise. Follows the daemon's
# Server-Sent Events (curl -N on /v1/jobs/ID/events); polls GET /v1/jobs/ID when the daemon has no events (404).
set -euo pipefail
usage() { echo "usage: $(basename "$0") JOB_ID   (TESSERA_URL, default http://127.0.0.1:8080; TESSERA_TOKEN; WATCH_INTERVAL seconds between polls, default 1)"; }
if [[ ${1:-} == -h || ${1:-} == --help ]]; then usage; exit 0; fi
if [[ $# -ne 1 ]]; then usage >&2; exit 2; fi
source "$(dirname "$0")/common.sh"

# One status line per job status document (a JSON object per line on stdin): "STATE<TAB>message".
status_line='
import json, sys
def line(s):
    p = s["progress"]
    eta = "?" if p.get("eta_s") is None else "%.1fs" % p["eta_s"]
    msg = "%-9s %3.0f%%  %d/%d spp  pass %d  %.1fs  eta %s  %.3g samples/s" % (
        s["state"], 100 * p["fraction"], p["samples_done"], p["samples_total"], p["passes"], p["elapsed_s"], eta,
        p["samples_per_s"])
    if s.get("stop_reason"): msg += "  stopped by " + s["stop_reason"]
    if s.get("error"): msg += "  error: " + s["error"]
    return msg
'

# The events stream: prints a line per state or progress event; exits 0 (succeeded), 1 (failed or cancelled) at the
# terminal state event, 3 when the stream ended before it.
sse_parser="$status_line"'
status, event, data = None, "", []
for raw in sys.stdin:
    raw = raw.rstrip("\r\n")
    if raw.startswith("event:"): event = raw[6:].strip()
    elif raw.startswith("data:"): data.append(raw[5:].lstrip(" "))
    elif raw == "" and data:
        d = json.loads("\n".join(data))
        if event == "state":
            status = d
            print(line(d), flush=True)
            if d["state"] in ("succeeded", "failed", "cancelled"):
                sys.exit(0 if d["state"] == "succeeded" else 1)
        elif event == "progress" and status:
            status["progress"] = d["progress"]
            print(line(status), flush=True)
        event, data = "", []
sys.exit(3)
'

headers=$(mktemp)
trap 'rm -f "$headers"' EXIT
set +e
curl -sS -N -D "$headers" -H 'Accept: text/event-stream' ${TESSERA_AUTH[@]+"${TESSERA_AUTH[@]}"} \
  "$TESSERA_URL/v1/jobs/$1/events" 2>/dev/null | python3 -c "$sse_parser"
rc=${PIPESTATUS[1]}
set -e
http=$(awk 'toupper($1) ~ /^HTTP/ {code=$2} END {print code}' "$headers")
if [[ $http == 200 && ( $rc == 0 || $rc == 1 ) ]]; then exit "$rc"; fi
if [[ -n $http && $http != 200 && $http != 404 ]]; then
  request GET "/v1/jobs/$1/events" >/dev/null  # prints the daemon's problem and exits 1
fi

# No events endpoint (404), or the stream ended early: poll.
while true; do
  status=$(request GET "/v1/jobs/$1")
  line=$(python3 -c "$status_line"'
s = json.load(sys.stdin)
print(s["state"] + "\t" + line(s))
' <<<"$status")
  state=${line%%$'\t'*}
  echo "${line#*$'\t'}"
  case $state in
    succeeded) exit 0 ;;
    failed | cancelled) exit 1 ;;
  esac
  sleep "${WATCH_INTERVAL:-1}"
done
