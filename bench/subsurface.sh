#!/usr/bin/env bash
# tessera's subsurface random walk against Blender Cycles' (Debian's blender 3.4, CPU) on the same subject: a UV
# sphere mesh of radius 1 (128 x 64 segments, 16k triangles) that is all subsurface (multiple-scattering albedo
# COLOR, mean free path RADIUS x [1, 0.5, 0.25], ior 1.4, roughness 0.3: tessera's `subsurface` material with alpha
# 0.3^2, Cycles' Principled BSDF with Subsurface 1 and method RANDOM_WALK) under a uniform grey sky, same resolution,
# samples, bounces and threads, no denoising or adaptive sampling. Prints each renderer's render time (tessera its
# own, without loading; Cycles the SPP-sample render minus a 1-sample one, bench/cycles_subsurface.py) and their
# ratio. The two are not the same model at the surface (Cycles leaves a walk through a diffuse lobe and samples the
# lights there; tessera through the rough dielectric), so the images differ; the figure is time per sample. The
# subject is bench/subsurface_scene.py's; GUIDING=0 renders tessera's plain random walk (render.subsurface_guiding).
#   SIZE=256 SPP=64 THREADS=2 COLOR=0.8 RADIUS=0.1 GUIDING=1 bench/subsurface.sh
set -euo pipefail
cd "$(dirname "$0")/.."
size=${SIZE:-256}; spp=${SPP:-64}; bounces=${BOUNCES:-8}; threads=${THREADS:-$(nproc)}
color=${COLOR:-0.8}; radius=${RADIUS:-0.1}
tessera=${TESSERA:-build/clients/cli/tessera}
command -v blender >/dev/null || { echo "subsurface: blender is not installed (apt-get install blender)" >&2; exit 2; }
[ -x "$tessera" ] || { echo "subsurface: build tessera first (make build)" >&2; exit 2; }
work=$(mktemp -d); trap 'rm -rf "$work"' EXIT
python3 bench/subsurface_scene.py "$size" "$spp" "$bounces" "$color" "$radius" "${GUIDING:-1}" > "$work/job.json"
t_tessera=$("$tessera" render "$work/job.json" -o "$work/tessera.exr" --threads "$threads" 2>&1 \
              | sed -n 's/.* spp in \([0-9.]*\)s.*/\1/p')
out=$(blender -b --factory-startup --python bench/cycles_subsurface.py -- "$work/cycles.exr" "$size" "$spp" \
        "$bounces" "$threads" "$color" "$radius" 1.4 0.3 2>&1)
t_cycles=$(echo "$out" | sed -n 's/^CYCLES_RENDER_SECONDS //p')
[ -n "$t_cycles" ] || { echo "$out" | tail -20 >&2; echo "subsurface: Cycles did not render" >&2; exit 1; }
python3 - "$t_tessera" "$t_cycles" "$size" "$spp" "$threads" <<'PY'
import sys
tt, tc = float(sys.argv[1]), float(sys.argv[2])
print(f"subsurface sphere {sys.argv[3]}x{sys.argv[3]}, {sys.argv[4]} spp, {sys.argv[5]} threads: "
      f"tessera {tt:.2f} s, Cycles (random walk) {tc:.2f} s, tessera / Cycles {tt / tc:.2f}")
PY
