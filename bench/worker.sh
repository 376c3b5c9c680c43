#!/usr/bin/env bash
# One job through a daemon, start to end: starts TESSERAD (default build/server/tesserad) on a fresh data directory,
# submits JOB (default proto/examples/cornell.json at WIDTH x HEIGHT, SPP; with GLTF=file, that asset is uploaded
# first and named as the job's scene.gltf, e.g. JOB=examples/duck/job.json GLTF=examples/duck/Duck.glb), waits for it to succeed, and prints the
# wall time from submission to success and the render time the job reports (elapsed_s). Run it with two daemons (a
# build that renders in worker processes and one that does not) under a timer to compare them:
#   TESSERAD=/path/to/old/tesserad bench/worker.sh
# Needs curl and python3.
set -euo pipefail
cd "$(dirname "$0")/.."
TESSERAD=${TESSERAD:-build/server/tesserad}
JOB=${JOB:-proto/examples/cornell.json}
WIDTH=${WIDTH:-256}
HEIGHT=${HEIGHT:-256}
SPP=${SPP:-64}
THREADS=${THREADS:-2}
data=$(mktemp -d)
port_file="$data/port"
cleanup() {
  [ -n "${pid:-}" ] && kill "$pid" 2>/dev/null && wait "$pid" 2>/dev/null
  rm -rf "$data"
}
trap cleanup EXIT
"$TESSERAD" --data-dir "$data/d" --port 0 --threads "$THREADS" --log-level warn >"$port_file" 2>/dev/null &
pid=$!
for _ in $(seq 200); do
  port=$(grep -o 'http://127.0.0.1:[0-9]*' "$port_file" | head -1 | sed 's/.*://') || true
  [ -n "${port:-}" ] && break
  sleep 0.05
done
url="http://127.0.0.1:$port"
asset=""
if [ -n "${GLTF:-}" ]; then
  asset=$(curl -sf -X POST "$url/v1/assets" -F "file=@$GLTF" | python3 -c 'import json,sys; print(json.load(sys.stdin)["id"])')
fi
doc=$(python3 -c 'import json,sys; d=json.load(open(sys.argv[1])); r=d.setdefault("render",{}); r["width"]=int(sys.argv[2]); r["height"]=int(sys.argv[3]); r["spp"]=int(sys.argv[4]); a=sys.argv[5]
if a: d["scene"]["gltf"]=a
print(json.dumps(d))' "$JOB" "$WIDTH" "$HEIGHT" "$SPP" "$asset")
start=$(date +%s.%N)
id=$(curl -sf -X POST "$url/v1/jobs" -H 'content-type: application/json' -d "$doc" | python3 -c 'import json,sys; print(json.load(sys.stdin)["id"])')
while :; do
  status=$(curl -sf "$url/v1/jobs/$id")
  state=$(printf '%s' "$status" | python3 -c 'import json,sys; print(json.load(sys.stdin)["state"])')
  case "$state" in succeeded) break ;; failed|cancelled) echo "job $state: $status" >&2; exit 1 ;; esac
  sleep 0.02
done
end=$(date +%s.%N)
elapsed=$(printf '%s' "$status" | python3 -c 'import json,sys; print(json.load(sys.stdin)["progress"]["elapsed_s"])')
echo "wall_s $(python3 -c "print(round($end - $start, 3))") render_s $elapsed"
