#!/usr/bin/env bash
# Time to a given noise, adaptive sampling against uniform sampling, on the Cornell box and a glTF example.
#
# Noise is measured as the issue's Cycles comparison measures it, each image against itself: two renders with
# different seeds, pixel values clamped to [0, 1], the RMS of their difference over sqrt(2) (one image's noise),
# relative to the image's mean. Uniform sampling is rendered at doubling spp; its time to reach each adaptive render's
# noise is interpolated between the two uniform renders around it (log time against log noise), and the figure is
# adaptive time over that uniform time (below 1: adaptive sampling reaches the noise sooner). Times are the render's
# own (`tessera render`'s summary, loading excluded), the mean of the two seeds' runs; an adaptive render's mean spp is
# the mean over its pixels.
#
#   bench/adaptive.sh [JOB.json|SCENE.glb ...]   (default: the Cornell box and examples/duck/job.json, the Duck under a
#                                                sky and a sun)
#   env: BUILD=build WIDTH=320 HEIGHT=320 THRESHOLDS="0.1 0.05 0.02 0.01" MAX_SPP=512 MIN_SPP=16 THREADS=<all>
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD=${BUILD:-build}
WIDTH=${WIDTH:-320}
HEIGHT=${HEIGHT:-320}
THRESHOLDS=${THRESHOLDS:-0.1 0.05 0.02 0.01}
MAX_SPP=${MAX_SPP:-512}
MIN_SPP=${MIN_SPP:-16}
TESSERA=$BUILD/clients/cli/tessera
[[ -x $TESSERA ]] || { echo "build $TESSERA first (cmake --build $BUILD --target tessera)" >&2; exit 1; }
command -v oiiotool >/dev/null || { echo "oiiotool not found (apt-get install openimageio-tools)" >&2; exit 1; }
threads=()
[[ -n ${THREADS:-} ]] && threads=(--threads "$THREADS")
scenes=("$@")
[[ ${#scenes[@]} -gt 0 ]] || scenes=(proto/examples/cornell.json examples/duck/job.json)
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

# render SCENE OUT.exr SEED OPTIONS...: prints the render's seconds and its mean samples per pixel
render() {
  local scene=$1 out=$2 seed=$3
  shift 3
  "$TESSERA" render "$scene" -o "$out" --width "$WIDTH" --height "$HEIGHT" --seed "$seed" "${threads[@]}" "$@" 2>&1 |
    sed -n 's/.*, \([0-9]*\) spp in \([0-9.]*\)s .*/\2 \1/p'
}

source bench/noise.sh

# measure SCENE NAME OPTIONS...: "seconds noise spp" of two seeds (the mean seconds and mean spp)
measure() {
  local scene=$1 name=$2
  shift 2
  local r1 r2
  r1=$(render "$scene" "$tmp/$name.1.exr" 1 "$@")
  r2=$(render "$scene" "$tmp/$name.2.exr" 2 "$@")
  awk -v a="$r1" -v b="$r2" -v n="$(noise "$tmp/$name.1.exr" "$tmp/$name.2.exr")" \
    'BEGIN { split(a, x, " "); split(b, y, " "); printf "%.3f %s %.0f\n", (x[1] + y[1]) / 2, n, (x[2] + y[2]) / 2 }'
}

printf 'adaptive against uniform sampling at %dx%d, min_spp %d, spp at most %d\n' "$WIDTH" "$HEIGHT" "$MIN_SPP" "$MAX_SPP"
for scene in "${scenes[@]}"; do
  echo "== $scene"
  : >"$tmp/uniform"
  for spp in 4 8 16 32 64 128 256 512 1024; do
    [[ $spp -le $MAX_SPP ]] || break
    read -r t n _ < <(measure "$scene" "u$spp" --spp "$spp")
    echo "$t $n" >>"$tmp/uniform"
    printf 'uniform   spp %5d          %8.3f s  noise %.5f\n' "$spp" "$t" "$n"
  done
  for threshold in $THRESHOLDS; do
    read -r t n m < <(measure "$scene" "a$threshold" --spp "$MAX_SPP" --min-spp "$MIN_SPP" --adaptive-threshold "$threshold")
    # The uniform time at noise n: log-log interpolation between the uniform renders on either side of it.
    awk -v t="$t" -v n="$n" -v m="$m" -v th="$threshold" '
      { ut[NR] = $1; un[NR] = $2 }
      END {
        u = -1
        for (i = 1; i < NR; ++i)
          if (un[i] >= n && un[i + 1] <= n) {
            f = (log(n) - log(un[i])) / (log(un[i + 1]) - log(un[i]))
            u = exp(log(ut[i]) + f * (log(ut[i + 1]) - log(ut[i])))
          }
        if (u < 0) printf "adaptive  threshold %-6s %8.3f s  noise %.5f  mean spp %4d  (outside the uniform renders'\'' noise)\n", th, t, n, m
        else printf "adaptive  threshold %-6s %8.3f s  noise %.5f  mean spp %4d  uniform %.3f s  adaptive/uniform %.2f\n", th, t, n, m, u, t / u
      }' "$tmp/uniform"
  done
done
