#!/usr/bin/env bash
# Guided against plain random walks (render.subsurface_guiding) on the subsurface benchmark's sphere
# (bench/subsurface_scene.py): a guided reference of REF_SPP samples, then each walk at SPP samples, RUNS times with
# other seeds. Prints each walk's median render time (tessera's own, without loading), its RMSE against the reference
# (RGB, relative to the reference's mean; the reference's own noise is REF_SPP / SPP times smaller in variance), and
# the RMSE it reaches in the guided walk's time (RMSE falls as 1 / sqrt(time)): the equal-time comparison.
#   SIZE=128 SPP=64 REF_SPP=2048 RUNS=3 THREADS=2 COLOR=0.8 RADIUS=0.1 bench/subsurface_guiding.sh
set -euo pipefail
cd "$(dirname "$0")/.."
size=${SIZE:-128}; spp=${SPP:-64}; ref_spp=${REF_SPP:-2048}; runs=${RUNS:-3}; threads=${THREADS:-$(nproc)}
color=${COLOR:-0.8}; radius=${RADIUS:-0.1}; bounces=${BOUNCES:-8}
tessera=${TESSERA:-build/clients/cli/tessera}
[ -x "$tessera" ] || { echo "subsurface_guiding: build tessera first (make build)" >&2; exit 2; }
command -v oiiotool >/dev/null || { echo "subsurface_guiding: oiiotool is missing (apt-get install openimageio-tools)" >&2; exit 2; }
work=$(mktemp -d); trap 'rm -rf "$work"' EXIT

# render JOB OUT SEED: prints the render time in seconds.
render() {
  "$tessera" render "$1" -o "$2" --seed "$3" --threads "$threads" 2>&1 | sed -n 's/.* spp in \([0-9.]*\)s.*/\1/p'
}
# mean of the squared RGB difference of two images, and the mean of the second
sq_error() {
  oiiotool "$1" --ch R,G,B "$2" --ch R,G,B --sub --dup --mul --printstats 2>&1 |
    sed -n 's/.*Stats Avg: \([-0-9.e]*\) \([-0-9.e]*\) \([-0-9.e]*\).*/\1 \2 \3/p' | awk '{ print ($1 + $2 + $3) / 3 }'
}
mean_of() {
  oiiotool "$1" --ch R,G,B --printstats 2>&1 |
    sed -n 's/.*Stats Avg: \([-0-9.e]*\) \([-0-9.e]*\) \([-0-9.e]*\).*/\1 \2 \3/p' | awk '{ print ($1 + $2 + $3) / 3 }'
}

python3 bench/subsurface_scene.py "$size" "$ref_spp" "$bounces" "$color" "$radius" 1 > "$work/ref.json"
render "$work/ref.json" "$work/ref.exr" 1000 >/dev/null
mean=$(mean_of "$work/ref.exr")
for mode in 1 0; do
  python3 bench/subsurface_scene.py "$size" "$spp" "$bounces" "$color" "$radius" "$mode" > "$work/job$mode.json"
  : > "$work/runs$mode"
  for run in $(seq 1 "$runs"); do
    t=$(render "$work/job$mode.json" "$work/out$mode.exr" "$run")
    echo "$t $(sq_error "$work/out$mode.exr" "$work/ref.exr")" >> "$work/runs$mode"
  done
done
python3 - "$work/runs1" "$work/runs0" "$mean" "$size" "$spp" "$ref_spp" "$threads" "$(cut -d' ' -f1-3 /proc/loadavg)" <<'PY'
import math, statistics, sys
def load(path):
    rows = [tuple(map(float, line.split())) for line in open(path) if line.strip()]
    return statistics.median(r[0] for r in rows), math.sqrt(statistics.median(r[1] for r in rows))
mean = float(sys.argv[3])
(tg, eg), (tp, ep) = load(sys.argv[1]), load(sys.argv[2])
print(f"subsurface sphere {sys.argv[4]}x{sys.argv[4]}, {sys.argv[5]} spp (reference {sys.argv[6]}), "
      f"{sys.argv[7]} threads, load {sys.argv[8]}")
print(f"  guided: {tg:.2f} s, RMSE {eg / mean:.4f}")
print(f"  plain:  {tp:.2f} s, RMSE {ep / mean:.4f}, at the guided walk's time {ep / mean * math.sqrt(tp / tg):.4f}")
print(f"  guided / plain: time {tg / tp:.2f}, equal-time RMSE {eg / (ep * math.sqrt(tp / tg)):.2f}, "
      f"efficiency (1 / (RMSE^2 time)) {(ep * ep * tp) / (eg * eg * tg):.2f}x")
PY
