#!/usr/bin/env bash
# Frame ranges through the daemon (render.frames of a submitted job): frames per hour of the 48-frame spinning cube
# rendered by one tesserad (SQLite), from its submission to its last frame, against the same range rendered locally
# by `tessera render --frames` (bench/frames.sh): what the daemon adds a frame (its worker process, the job's files
# and progress, the status a frame).
#   bench/frames_daemon.sh         (env: BUILD=build WIDTH=640 HEIGHT=360 SPP=16 FRAMES=1-48 CHUNK=1 THREADS=<all>
#                                   LOCAL=1: 0 skips the local range)
# Figures, not a test: run it on an otherwise idle machine.
set -euo pipefail
cd "$(dirname "$0")/.."
build=${BUILD:-build}
tesserad=$build/server/tesserad
tessera=$build/clients/cli/tessera
[[ -x $tesserad && -x $tessera ]] || { echo "frames_daemon: build $tesserad and $tessera first" >&2; exit 2; }
command -v curl >/dev/null || { echo "frames_daemon: needs curl" >&2; exit 2; }
width=${WIDTH:-640}; height=${HEIGHT:-360}; spp=${SPP:-16}; frames=${FRAMES:-1-48}; chunk=${CHUNK:-1}
start=${frames%-*}; end=${frames#*-}
threads=${THREADS:-$(nproc)}
work=$(mktemp -d)
pid=""
cleanup() {
  [[ -n $pid ]] && kill -TERM "$pid" 2>/dev/null && wait "$pid" 2>/dev/null
  rm -rf "$work"
}
trap cleanup EXIT
printf '%s, %s hardware threads, %s render threads\n' \
  "$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ *//')" "$(nproc)" "$threads"

"$tesserad" --port 0 --listen 127.0.0.1 --data-dir "$work/data" --threads "$threads" --max-jobs 1 --log-level warn \
  >"$work/out" 2>"$work/err" &
pid=$!
url=""
for _ in $(seq 100); do
  url=$(sed -n 's/.*listening on \(http:[^ ]*\).*/\1/p' "$work/out" | head -1)
  [[ -n $url ]] && break
  sleep 0.1
done
[[ -n $url ]] || { echo "frames_daemon: the daemon did not start" >&2; cat "$work/err" >&2; exit 1; }
url=${url%/}
bench=frames_daemon
start_frame=$start; end_frame=$end
source bench/frames_range.sh
read -r id wall <<<"$(run_range "$url")"
[[ -n $wall ]] || exit 1
n=$(curl -sS "$url/v1/jobs/$id" | field '["frames"]["done"]')
printf 'daemon, one node, chunk %s: %d frames at %sx%s, %s spp: %.1f s from submission to the last frame, %.2f s a frame, %.0f frames/hour\n' \
  "$chunk" "$n" "$width" "$height" "$spp" "$wall" "$(echo "$wall / $n" | bc -l)" "$(echo "3600 * $n / $wall" | bc -l)"
[[ ${LOCAL:-1} == 0 ]] && exit 0
t0=$(date +%s.%N)
"$tessera" render examples/spinning_cube/job.json --frames "$frames" --width "$width" --height "$height" --spp "$spp" \
  --threads "$threads" -q -o "$work/local.png"
t1=$(date +%s.%N)
wall=$(echo "$t1 - $t0" | bc -l)
printf 'tessera render --frames, locally: %.1f s, %.2f s a frame, %.0f frames/hour\n' "$wall" "$(echo "$wall / $n" | bc -l)" \
  "$(echo "3600 * $n / $wall" | bc -l)"
