#!/usr/bin/env bash
# tessera's subsurface random walk against Blender Cycles' (Debian's blender 3.4, CPU) on the same subject: a UV
# sphere mesh of radius 1 (128 x 64 segments, 16k triangles) that is all subsurface (multiple-scattering albedo
# COLOR, mean free path RADIUS x [1, 0.5, 0.25], ior 1.4, roughness 0.3: tessera's `subsurface` material with alpha
# 0.3^2, Cycles' Principled BSDF with Subsurface 1 and method RANDOM_WALK) under a uniform grey sky, same resolution,
# samples, bounces and threads, no denoising or adaptive sampling. Prints each renderer's render time (tessera its
# own, without loading; Cycles the SPP-sample render minus a 1-sample one, bench/cycles_subsurface.py) and their
# ratio. The two are not the same model at the surface (Cycles leaves a walk through a diffuse lobe and samples the
# lights there; tessera through the rough dielectric), so the images differ; the figure is time per sample.
#   SIZE=256 SPP=64 THREADS=2 COLOR=0.8 RADIUS=0.1 bench/subsurface.sh
set -euo pipefail
cd "$(dirname "$0")/.."
size=${SIZE:-256}; spp=${SPP:-64}; bounces=${BOUNCES:-8}; threads=${THREADS:-$(nproc)}
color=${COLOR:-0.8}; radius=${RADIUS:-0.1}
tessera=${TESSERA:-build/clients/cli/tessera}
command -v blender >/dev/null || { echo "subsurface: blender is not installed (apt-get install blender)" >&2; exit 2; }
[ -x "$tessera" ] || { echo "subsurface: build tessera first (make build)" >&2; exit 2; }
work=$(mktemp -d); trap 'rm -rf "$work"' EXIT
python3 - "$size" "$spp" "$bounces" "$color" "$radius" > "$work/job.json" <<'PY'
import json, math, sys
size, spp, bounces, color, radius = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), float(sys.argv[4]), float(sys.argv[5])
seg, rings = 128, 64  # Blender's primitive_uv_sphere_add(segments=128, ring_count=64)
pos, nrm, idx = [], [], []
for r in range(rings + 1):
    th = math.pi * r / rings
    for s in range(seg):
        ph = 2 * math.pi * s / seg
        p = (math.sin(th) * math.cos(ph), math.sin(th) * math.sin(ph), math.cos(th))
        pos += p; nrm += p
for r in range(rings):
    for s in range(seg):
        a, b = r * seg + s, r * seg + (s + 1) % seg
        c, d = a + seg, b + seg
        if r > 0: idx += [a, c, b]
        if r < rings - 1: idx += [b, c, d]
job = {"kind": "scene", "scene": {
    "materials": {"skin": {"type": "subsurface", "ior": 1.4, "roughness": 0.09, "subsurface_color": color,
                           "subsurface_radius": radius, "subsurface_radius_scale": [1, 0.5, 0.25]}},
    "objects": [{"shape": "mesh", "positions": pos, "normals": nrm, "indices": idx, "material": "skin"}],
    "camera": {"from": [0, 0, 3.5], "to": [0, 0, 0], "up": [0, 1, 0], "fov_deg": 40},
    "environment": {"color": 0.8}},
    "render": {"width": size, "height": size, "spp": spp, "max_depth": bounces, "seed": 7}}
print(json.dumps(job))
PY
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
