#!/usr/bin/env python3
# The subsurface benchmarks' subject (bench/subsurface.sh, bench/subsurface_guiding.sh): a UV sphere mesh of radius 1
# (128 x 64 segments, as Blender's primitive_uv_sphere_add(segments=128, ring_count=64)) that is all subsurface
# (multiple-scattering albedo COLOR, mean free path RADIUS x [1, 0.5, 0.25], ior 1.4, roughness 0.3) under a uniform
# grey sky, as a tessera job on stdout.
#   bench/subsurface_scene.py SIZE SPP BOUNCES COLOR RADIUS [GUIDING]
import json, math, sys
size, spp, bounces, color, radius = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), float(sys.argv[4]), float(sys.argv[5])
guiding = len(sys.argv) < 7 or sys.argv[6] not in ('0', 'false', 'off')
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
if not guiding:
    job["render"]["subsurface_guiding"] = False
print(json.dumps(job))
