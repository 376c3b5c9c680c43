#!/usr/bin/env bash
# Time to equal noise against Blender's Cycles with adaptive sampling (Debian's blender, CPU, Embree).
#
# Per scene, Cycles renders with adaptive sampling at its defaults (noise threshold 0.01, automatic min samples, at
# most MAX_SPP samples) twice, with seeds 1 and 2; its noise is measured against itself (bench/noise.sh: the RMS of
# the two renders' difference over sqrt(2), pixel values clamped to [0, 1], relative to the mean) and its time is the
# mean of the two renders' (bench/cycles_render.py: the render less a 1-sample render, so import, sync and BVH build
# are left out). tessera then renders the same glTF with its adaptive sampling (at most MAX_SPP samples, min_spp
# MIN_SPP) at thresholds halved (or doubled) from START until its noise, measured the same way, brackets Cycles'; its
# time at Cycles' noise is interpolated between the two bracketing thresholds (log time against log noise), and the
# figure is that time over Cycles' (below 1: tessera reaches Cycles' noise sooner). tessera's times are its own
# (`tessera render`'s summary, loading excluded).
#
# The second figure does the same with tessera's denoiser on (render.denoise regression). Its noise is measured the
# same way, two denoised renders with different seeds: that is the denoised image's variance, not its error, since
# the denoiser's bias (what it blurs) is the same in both renders and cancels in their difference. It says how soon
# the denoised image is as steady as Cycles' raw one, not that it is as close to the truth.
#
# Scenes: the Cornell box as glTF (bench/cornell_to_gltf.py, black world), and each .glb under SCENES_DIR under a
# uniform grey world (WORLD), framed by bench/gltf_with_camera.py where the asset has no camera. Each figure is the
# median of RUNS runs; the load average is printed beside it (the machine may be shared).
#   SIZE=256 RUNS=3 bench/cycles_adaptive.sh [SCENE.glb ...]   (needs: apt-get install blender python3-numpy
#                                                               openimageio-tools)
#   env: BUILD=build BOUNCES=8 MAX_SPP=4096 MIN_SPP=16 CYCLES_THRESHOLD=0.01 START=0.04 WORLD=0.8 DENOISE=1
#        THREADS=<all> SCENES_DIR=../shared/scenes (beside the checkout)
set -euo pipefail
cd "$(dirname "$0")/.."
SIZE=${SIZE:-256}
RUNS=${RUNS:-3}
BOUNCES=${BOUNCES:-8}
MAX_SPP=${MAX_SPP:-4096}
MIN_SPP=${MIN_SPP:-16}
CYCLES_THRESHOLD=${CYCLES_THRESHOLD:-0.01}
START=${START:-0.04}
WORLD=${WORLD:-0.8}
DENOISE=${DENOISE:-1}
THREADS=${THREADS:-$(nproc)}
SCENES_DIR=${SCENES_DIR:-../shared/scenes}
TESSERA=${BUILD:-build}/clients/cli/tessera
command -v blender >/dev/null || { echo "cycles_adaptive: blender is not installed" >&2; exit 2; }
command -v oiiotool >/dev/null || { echo "cycles_adaptive: oiiotool not found (openimageio-tools)" >&2; exit 2; }
[[ -x $TESSERA ]] || { echo "cycles_adaptive: build $TESSERA first" >&2; exit 2; }
source bench/noise.sh
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

# The scenes: NAME GLTF WORLD, one a line.
python3 - "$SIZE" >"$tmp/cornell-job.json" <<'PY'
import json, sys
j = json.load(open("proto/examples/cornell.json")); s = int(sys.argv[1])
j["render"].update({"width": s, "height": s}); print(json.dumps(j))
PY
python3 bench/cornell_to_gltf.py "$tmp/cornell-job.json" "$tmp/cornell.gltf"
echo "cornell $tmp/cornell.gltf 0" >"$tmp/scenes"
assets=("$@")
[[ ${#assets[@]} -gt 0 ]] || mapfile -t assets < <(ls "$SCENES_DIR"/*/*.glb)
for glb in "${assets[@]}"; do
  name=$(basename "$glb" .glb)
  python3 bench/gltf_with_camera.py "$glb" "$tmp/$name.glb"
  echo "$name $tmp/$name.glb $WORLD" >>"$tmp/scenes"
done

# cycles GLTF WORLD OUT.exr SEED: prints the adaptive render's seconds
cycles() {
  local out t
  out=$(blender -b --factory-startup --python bench/cycles_render.py -- "$1" "$3" "$SIZE" "$SIZE" "$MAX_SPP" \
    "$BOUNCES" "$THREADS" "$4" "$CYCLES_THRESHOLD" 0 "$2" 2>&1)
  t=$(echo "$out" | sed -n 's/^CYCLES_RENDER_SECONDS //p')
  [[ -n $t ]] || { echo "$out" | tail -20 >&2; echo "cycles_adaptive: Cycles did not render $1" >&2; exit 1; }
  echo "$t"
}

# tessera GLTF WORLD OUT.exr SEED THRESHOLD [OPTIONS...]: prints "seconds mean-spp"
tessera() {
  local gltf=$1 world=$2 out=$3 seed=$4 threshold=$5
  shift 5
  python3 -c "import json, sys; print(json.dumps({'kind': 'scene', 'scene': {'gltf': sys.argv[1],
    'environment': {'color': float(sys.argv[2])}}, 'render': {'max_depth': $BOUNCES}}))" \
    "$(basename "$gltf")" "$world" >"$(dirname "$gltf")/job.json"
  "$TESSERA" render "$(dirname "$gltf")/job.json" -o "$out" --width "$SIZE" --height "$SIZE" --seed "$seed" \
    --spp "$MAX_SPP" --min-spp "$MIN_SPP" --adaptive-threshold "$threshold" --threads "$THREADS" "$@" 2>&1 |
    sed -n 's/.*, \([0-9]*\) spp in \([0-9.]*\)s .*/\2 \1/p' | tail -1
}

# tessera_point GLTF WORLD THRESHOLD [OPTIONS...]: "seconds noise mean-spp" of seeds 1 and 2 (mean seconds and spp)
tessera_point() {
  local gltf=$1 world=$2 threshold=$3
  shift 3
  local a b
  a=$(tessera "$gltf" "$world" "$tmp/t1.exr" 1 "$threshold" "$@")
  b=$(tessera "$gltf" "$world" "$tmp/t2.exr" 2 "$threshold" "$@")
  awk -v a="$a" -v b="$b" -v n="$(noise "$tmp/t1.exr" "$tmp/t2.exr")" \
    'BEGIN { split(a, x, " "); split(b, y, " "); printf "%.3f %s %.0f\n", (x[1] + y[1]) / 2, n, (x[2] + y[2]) / 2 }'
}

# time_to_noise GLTF WORLD NOISE [OPTIONS...]: tessera's seconds to reach NOISE, interpolated (log-log) between the
# two thresholds whose noises bracket it; prints "seconds threshold-range mean-spp-range" (an upper bound where even
# min_spp everywhere is below the noise)
time_to_noise() {
  local gltf=$1 world=$2 target=$3
  shift 3
  local th=$START prev="" cur t n m
  for _ in 1 2 3 4 5 6 7 8; do
    cur=$(tessera_point "$gltf" "$world" "$th" "$@")
    read -r t n m <<<"$cur"
    echo "    tessera threshold $th: $t s, noise $n, mean spp $m $*" >&2
    if [[ -n $prev ]]; then
      local pn
      pn=$(echo "$prev" | cut -d' ' -f3)
      # Bracketed: one side above the target, the other at or below it.
      if awk -v a="$pn" -v b="$n" -v c="$target" 'BEGIN { exit !((a - c) * (b - c) <= 0) }'; then
        awk -v p="$prev" -v t="$t" -v n="$n" -v m="$m" -v th="$th" -v c="$target" 'BEGIN {
          split(p, q, " "); f = (log(c) - log(q[3])) / (log(n) - log(q[3]))
          printf "%.3f %s-%s %d-%d\n", exp(log(q[2]) + f * (log(t) - log(q[2]))), q[1], th, q[4], m }'
        return
      fi
    fi
    prev="$th $t $n $m"
    # Noisier than the target: a lower threshold; cleaner: a higher one.
    th=$(awk -v th="$th" -v n="$n" -v c="$target" 'BEGIN { printf "%.6g", (n > c ? th / 2 : th * 2) }')
  done
  # Never bracketed: cleaner than the target even where every pixel stops at min_spp (the denoiser can be); the
  # last render's time is then an upper bound, its thresholds marked with ">=".
  read -r th t n m <<<"$prev"
  if awk -v n="$n" -v c="$target" 'BEGIN { exit !(n <= c) }'; then echo "$t >=$th $m"; else echo "nan - -"; fi
}

median() { sort -g | awk '{ v[NR] = $1 } END { print NR % 2 ? v[(NR + 1) / 2] : (v[NR / 2] + v[NR / 2 + 1]) / 2 }'; }

printf 'tessera adaptive sampling against Cycles (threshold %s, automatic min samples), %dx%d, at most %d spp, %d bounces, %d threads, median of %d runs\n' \
  "$CYCLES_THRESHOLD" "$SIZE" "$SIZE" "$MAX_SPP" "$BOUNCES" "$THREADS" "$RUNS"
while read -r name gltf world; do
  echo "== $name"
  : >"$tmp/ratios"
  : >"$tmp/ratios_dn"
  for run in $(seq "$RUNS"); do
    c1=$(cycles "$gltf" "$world" "$tmp/c1.exr" 1)
    c2=$(cycles "$gltf" "$world" "$tmp/c2.exr" 2)
    tc=$(awk -v a="$c1" -v b="$c2" 'BEGIN { printf "%.3f", (a + b) / 2 }')
    nc=$(noise "$tmp/c1.exr" "$tmp/c2.exr")
    read -r tt range spp < <(time_to_noise "$gltf" "$world" "$nc")
    line="run $run: Cycles $tc s, noise $nc; tessera adaptive $tt s (thresholds $range, mean spp $spp)"
    awk -v a="$tt" -v b="$tc" 'BEGIN { printf "%.3f\n", a / b }' >>"$tmp/ratios"
    if [[ $DENOISE == 1 ]]; then
      read -r td range spp < <(time_to_noise "$gltf" "$world" "$nc" --denoise regression)
      line+="; adaptive + denoiser $td s (thresholds $range, mean spp $spp)"
      awk -v a="$td" -v b="$tc" 'BEGIN { printf "%.3f\n", a / b }' >>"$tmp/ratios_dn"
    fi
    echo "  $line; load $(cut -d' ' -f1-3 /proc/loadavg)"
  done
  printf '%s: tessera/Cycles time to Cycles'\'' noise: adaptive %s' "$name" "$(median <"$tmp/ratios")"
  [[ $DENOISE == 1 ]] && printf ', adaptive + denoiser %s' "$(median <"$tmp/ratios_dn")"
  printf '   (load %s)\n' "$(cut -d' ' -f1-3 /proc/loadavg)"
done <"$tmp/scenes"
