#!/usr/bin/env bash
# Time per sample of a smoke-like heterogeneous medium from an OpenVDB grid: a procedural puff (a sphere of radius
# 0.8 whose density falls off towards its edge, carved by a sum of sines at three octaves, 0 where the sum cuts it
# away) on a grid of N^3 voxels written with Debian's python3-openvdb, in a unit box with an `interface` boundary,
# scattering (sigma_s 8, sigma_a 0.5 per unit at density 1, g 0.4) under a lamp and a dim sky, rendered by the path
# tracer, once with each majorant that delta and ratio tracking sample against (the medium's "majorant": "global",
# the grid's largest extinction, and "grid", a coarse grid of them); prints each's render time and time per sample,
# and the relative difference of the two images' means (the same in expectation).
#   N=128 SIZE=256 SPP=32 THREADS=2 bench/grid_medium.sh
set -euo pipefail
cd "$(dirname "$0")/.."
n=${N:-128}; size=${SIZE:-256}; spp=${SPP:-32}; threads=${THREADS:-$(nproc)}
tessera=${TESSERA:-build/clients/cli/tessera}
/usr/bin/python3 -c 'import pyopenvdb' 2>/dev/null ||
  { echo "grid_medium: python3-openvdb is not installed (apt-get install python3-openvdb)" >&2; exit 2; }
[ -x "$tessera" ] || { echo "grid_medium: build tessera first (make build)" >&2; exit 2; }
work=$(mktemp -d); trap 'rm -rf "$work"' EXIT
/usr/bin/python3 - "$work/smoke.vdb" "$n" <<'PY'
import sys
import numpy as np
import pyopenvdb as vdb
path, n = sys.argv[1], int(sys.argv[2])
x = (np.arange(n) + 0.5) / n * 2 - 1  # voxel centres over [-1, 1]
X, Y, Z = np.meshgrid(x, x, x, indexing="ij")
r = np.sqrt(X**2 + Y**2 + Z**2)
noise = sum(np.sin(f * X + 1.7 * k) * np.sin(f * Y + 2.3 * k) * np.sin(f * Z + 0.9 * k) / f
            for k, f in enumerate((3.0, 7.0, 15.0)))
density = np.clip((0.8 - r) / 0.3, 0, 1) * np.clip(0.5 + 1.5 * noise, 0, None)
grid = vdb.FloatGrid()
grid.copyFromArray(density.astype(np.float32), tolerance=1e-4)
grid.name = "density"
grid.transform = vdb.createLinearTransform(voxelSize=1.0 / n)  # the grid spans [0, 1]^3
vdb.write(path, grids=[grid])
PY
for majorant in global grid; do
  /usr/bin/python3 - "$size" "$spp" "$majorant" > "$work/job-$majorant.json" <<'PY'
import json, sys
size, spp, majorant = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
box = [0 if (v >> a) & 1 == 0 else 1 for v in range(8) for a in range(3)]
faces = [0, 4, 6, 0, 6, 2, 1, 3, 7, 1, 7, 5, 0, 1, 5, 0, 5, 4, 2, 6, 7, 2, 7, 3, 0, 2, 3, 0, 3, 1, 4, 5, 7, 4, 7, 6]
job = {"kind": "scene", "scene": {
    "materials": {"boundary": {"type": "interface"}, "floor": {"type": "lambert", "albedo": 0.5},
                  "lamp": {"type": "emission", "radiance": 8}},
    "objects": [{"shape": "mesh", "positions": box, "indices": faces, "material": "boundary",
                 "medium": {"grid": "smoke.vdb", "sigma_a": 0.5, "sigma_s": 8, "g": 0.4, "majorant": majorant}},
                {"shape": "rectangle", "corner": [-3, 0, 4], "edge1": [7, 0, 0], "edge2": [0, 0, -7],
                 "material": "floor"},
                {"shape": "sphere", "center": [1.5, 3, 1.5], "radius": 0.5, "material": "lamp"}],
    "camera": {"from": [1.8, 1.2, 2.8], "to": [0.5, 0.45, 0.5], "fov_deg": 40},
    "environment": {"color": 0.15}},
    "render": {"width": size, "height": size, "spp": spp, "seed": 7}}
print(json.dumps(job))
PY
  out=$("$tessera" render "$work/job-$majorant.json" -o "$work/$majorant.exr" --threads "$threads" 2>&1) ||
    { echo "$out" >&2; exit 1; }
  t=$(echo "$out" | sed -n 's/.* spp in \([0-9.]*\)s.*/\1/p')
  /usr/bin/python3 -c "import sys; t, spp, size = float(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]); \
print(f'smoke grid {sys.argv[4]}^3, {size}x{size}, {spp} spp, majorant {sys.argv[5]}: {t:.2f} s, ' \
      f'{t / spp * 1000:.1f} ms per sample')" "$t" "$spp" "$size" "$n" "$majorant"
done
