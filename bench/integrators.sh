#!/usr/bin/env bash
# Equal-time error of the integrators: path, bdpt and light render each scene for the same time, and their RMSE
# against a long reference render is printed (linear radiance, every pixel and channel, by OpenImageIO's idiff).
#
#   bench/integrators.sh [SCENE.json...]      (default: the Cornell box, the caustic and the room lit through a gap)
#   env: BUILD=build SECONDS_EACH=10 REF_SECONDS=300 REF_INTEGRATOR=bdpt SIZE=256 THREADS=<all> INTEGRATORS="path bdpt light"
#        SEED=7 REF_SEED=99 (other seeds give another sample of the figures, for their spread)
#
# The reference is one long render by REF_INTEGRATOR at another seed; a time limit ends a render after the pass that
# crosses it, so each line also says how many samples per pixel it reached and how long it took.
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD=${BUILD:-build}
SECONDS_EACH=${SECONDS_EACH:-10}
REF_SECONDS=${REF_SECONDS:-300}
REF_INTEGRATOR=${REF_INTEGRATOR:-bdpt}
SIZE=${SIZE:-256}
INTEGRATORS=${INTEGRATORS:-path bdpt light}
SEED=${SEED:-7}
REF_SEED=${REF_SEED:-99}
TESSERA=$BUILD/clients/cli/tessera
threads=()
[[ -n ${THREADS:-} ]] && threads=(--threads "$THREADS")
[[ -x $TESSERA ]] || { echo "build $TESSERA first (cmake --build $BUILD --target tessera)" >&2; exit 1; }
command -v idiff >/dev/null || { echo "idiff not found (apt-get install openimageio-tools)" >&2; exit 1; }
scenes=("$@")
[[ ${#scenes[@]} -gt 0 ]] || scenes=(proto/examples/cornell.json proto/examples/caustic.json proto/examples/room_gap.json)
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

# render NAME INTEGRATOR SECONDS SEED: renders to $tmp/NAME.exr, prints "spp seconds" (from tessera's summary line:
# "tessera: WxH, N spp in S s ...", the render time without loading).
render() {
  "$TESSERA" render "$scene" --width "$SIZE" --height "$SIZE" --spp 65536 --time-limit "$3" --seed "$4" \
    --integrator "$2" "${threads[@]}" -o "$tmp/$1.exr" 2>"$tmp/$1.log"
  sed -n 's/^tessera: [0-9]*x[0-9]*, \([0-9]*\) spp in \([0-9.]*\)s.*/\1 \2/p' "$tmp/$1.log"
}
rmse() { { idiff -v -a "$1" "$2" 2>/dev/null || true; } | sed -n 's/^ *RMS error = \([0-9.e+-]*\).*/\1/p'; }

printf '%-12s %-6s %8s %8s %12s %10s\n' scene integ spp seconds rmse vs_path
for scene in "${scenes[@]}"; do
  name=$(basename "$scene" .json)
  read -r ref_spp ref_s < <(render "$name-ref" "$REF_INTEGRATOR" "$REF_SECONDS" "$REF_SEED")
  printf '%-12s %-6s %8s %8.1f %12s\n' "$name" "ref:$REF_INTEGRATOR" "$ref_spp" "$ref_s" "-"
  path_rmse=
  for integ in $INTEGRATORS; do
    read -r spp s < <(render "$name-$integ" "$integ" "$SECONDS_EACH" "$SEED")
    e=$(rmse "$tmp/$name-ref.exr" "$tmp/$name-$integ.exr")
    [[ $integ == path ]] && path_rmse=$e
    ratio=-
    [[ -n $path_rmse ]] && ratio=$(echo "scale=3; $e / $path_rmse" | bc)
    printf '%-12s %-6s %8s %8.1f %12s %10s\n' "$name" "$integ" "$spp" "$s" "$e" "$ratio"
  done
done
