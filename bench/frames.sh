#!/usr/bin/env bash
# Frame ranges (render.frames, `tessera render --frames`): frames per hour of an animated glTF asset rendered locally,
# and the overhead a frame costs besides its samples: the range again at 1 sample per pixel, its time a frame, the
# part of it spent loading the asset and building the BVH (the importer poses the nodes as it reads them, so each
# frame reads the asset again), and, for comparison, one `tessera render --time` process per frame.
#
#   bench/frames.sh [JOB.json]       (default: examples/spinning_cube/job.json, 48 frames)
#   env: BUILD=build WIDTH=640 HEIGHT=360 SPP=16 FRAMES=1-48 THREADS=<all> STILLS=8
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD=${BUILD:-build}
TESSERA=$BUILD/clients/cli/tessera
job=${1:-examples/spinning_cube/job.json}
[[ -x $TESSERA && -x $BUILD/clients/cli/tessera-render ]] || { echo "build $TESSERA first" >&2; exit 1; }
size=(--width "${WIDTH:-640}" --height "${HEIGHT:-360}")
threads=()
[[ -n ${THREADS:-} ]] && threads=(--threads "$THREADS")
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
printf '%s, %s hardware threads\n' "$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ *//')" "$(nproc)"

# range SPP: renders the range, prints its wall time and the summary line's load+BVH a frame.
range() {
  local t0 t1
  t0=$(date +%s.%N)
  "$TESSERA" render "$job" --frames "${FRAMES:-1-48}" "${size[@]}" --spp "$1" "${threads[@]}" -o "$tmp/frame.png" \
    2>"$tmp/log"
  t1=$(date +%s.%N)
  local load
  load=$(sed -n 's/.*of which load+BVH \([0-9.]*\)s.*/\1/p' "$tmp/log")
  echo "$(echo "$t1 - $t0" | bc -l) $load"
}
read -r wall load < <(range "${SPP:-16}")
frames=$(ls "$tmp"/frame.*.png | wc -l)
printf '%d frames at %sx%s, %s spp: %.1f s, %.2f s a frame, %.0f frames/hour (load+BVH %.4f s a frame)\n' \
  "$frames" "${WIDTH:-640}" "${HEIGHT:-360}" "${SPP:-16}" "$wall" "$(echo "$wall / $frames" | bc -l)" \
  "$(echo "3600 * $frames / $wall" | bc -l)" "$load"
rm -f "$tmp"/frame.*.png
read -r wall1 load1 < <(range 1)
printf 'the same at 1 spp: %.2f s, %.3f s a frame (load+BVH %.4f s a frame)\n' "$wall1" \
  "$(echo "$wall1 / $frames" | bc -l)" "$load1"
# One process per frame, as one job per frame would be rendered: what the range saves.
n=${STILLS:-8}
t0=$(date +%s.%N)
for i in $(seq "$n"); do
  "$TESSERA" render "$job" --frames "$i" "${size[@]}" --spp 1 "${threads[@]}" -q -o "$tmp/still.png"
done
t1=$(date +%s.%N)
printf 'one tessera render process a frame at 1 spp: %.3f s a frame (%d frames)\n' "$(echo "($t1 - $t0) / $n" | bc -l)" "$n"
