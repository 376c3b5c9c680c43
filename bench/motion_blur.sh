#!/usr/bin/env bash
# Motion blur (render.shutter): what a shutter costs a frame of an animated glTF asset rendered locally, with its
# motion sampled at 2 and at 8 time steps, against the same frames without one. The frames are rendered as a range
# (`tessera render --frames`), each frame's time the range's wall time over its frames, its load and BVH build
# included (under a shutter the importer poses the asset once a time step, and the BVH holds every step).
#
#   bench/motion_blur.sh [JOB.json]   (default: examples/spinning_cube/job.json)
#   env: BUILD=build WIDTH=640 HEIGHT=360 SPP=16 FRAMES=1-8 THREADS=<all> SHUTTER=-0.25:0.25 ROUNDS=3
# Figures, not a test: run it on an otherwise idle machine.
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD=${BUILD:-build}
TESSERA=$BUILD/clients/cli/tessera
job=${1:-examples/spinning_cube/job.json}
[[ -x $TESSERA ]] || { echo "build $TESSERA first" >&2; exit 1; }
size=(--width "${WIDTH:-640}" --height "${HEIGHT:-360}" --spp "${SPP:-16}")
threads=()
[[ -n ${THREADS:-} ]] && threads=(--threads "$THREADS")
frames=${FRAMES:-1-8}
shutter=${SHUTTER:--0.25:0.25}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
printf '%s, %s hardware threads\n' "$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ *//')" "$(nproc)"

# frame_seconds [OPTIONS...]: the range's wall time a frame, and the load+BVH a frame its summary lines give.
frame_seconds() {
  local t0 t1 n load
  t0=$(date +%s.%N)
  "$TESSERA" render "$job" --frames "$frames" "${size[@]}" "${threads[@]}" "$@" -o "$tmp/frame.png" 2>"$tmp/log"
  t1=$(date +%s.%N)
  n=$(ls "$tmp"/frame.*.png | wc -l)
  rm -f "$tmp"/frame.*.png
  load=$(sed -n 's/.*of which load+BVH \([0-9.]*\)s.*/\1/p' "$tmp/log")
  echo "$(echo "($t1 - $t0) / $n" | bc -l) $load"
}
# Rounds of the three, in turn (none, 2 steps, 8 steps, none, ...), so that a machine whose speed drifts slows them
# alike; each figure is the median of its rounds.
rounds=${ROUNDS:-3}
declare -A secs loads
for r in $(seq "$rounds"); do
  for steps in 0 2 8; do
    opts=()
    ((steps > 0)) && opts=(--shutter "$shutter:$steps")
    read -r s l < <(frame_seconds "${opts[@]}")
    secs[$steps]+="$s "
    loads[$steps]+="$l "
  done
done
median() { tr ' ' '\n' <<<"$1" | grep . | sort -g | awk '{v[NR] = $1} END {print v[int((NR + 1) / 2)]}'; }
none=$(median "${secs[0]}")
printf 'frames %s at %sx%s, %s spp, medians of %d rounds\n' "$frames" "${WIDTH:-640}" "${HEIGHT:-360}" "${SPP:-16}" \
  "$rounds"
printf '  no shutter:                  %.3f s a frame (load+BVH %.4f s)\n' "$none" "$(median "${loads[0]}")"
for steps in 2 8; do
  blurred=$(median "${secs[$steps]}")
  printf '  shutter %s, %d steps: %.3f s a frame (load+BVH %.4f s), %.2fx the frame without\n' "$shutter" "$steps" \
    "$blurred" "$(median "${loads[$steps]}")" "$(echo "$blurred / $none" | bc -l)"
done
