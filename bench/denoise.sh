#!/usr/bin/env bash
# The denoiser's figures (renderer/denoise.h): relative MSE against a long reference at several sample counts, for the
# image as rendered and denoised, and the denoiser's time on a 1920 x 1080 image, on this machine's processor.
#
#   bench/denoise.sh [JOB.json]            (default: the Cornell box)
#   env: BUILD=build WIDTH=256 HEIGHT=256 REF_SPP=16384 SPP=16,64,256,1024 RUNS=3 THREADS=<all>
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD=${BUILD:-build}
BENCH=$BUILD/bench/tessera-denoise-bench
job=${1:-proto/examples/cornell.json}
[[ -x $BENCH ]] || { echo "build $BENCH first (cmake --build $BUILD --target tessera-denoise-bench)" >&2; exit 1; }
threads=()
[[ -n ${THREADS:-} ]] && threads=(--threads "$THREADS")
printf '%s, %s hardware threads\n' "$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ *//')" "$(nproc)"
"$BENCH" "$job" --size "${WIDTH:-256}" "${HEIGHT:-256}" --ref-spp "${REF_SPP:-16384}" --spp "${SPP:-16,64,256,1024}" \
  --runs "${RUNS:-3}" "${threads[@]}"
