#!/usr/bin/env bash
# Time per sample of a smoke-like heterogeneous medium from an OpenVDB grid: examples/smoke/smoke.json (a unit box
# of scattering smoke with an `interface` boundary, under a lamp and a dim sky) with its grid made by bench/smoke_vdb.py at N^3 voxels (Debian's python3-openvdb), rendered by the path
# tracer once with each majorant that delta and ratio tracking sample against (the medium's "majorant": "global", the
# grid's largest extinction, and "grid", a coarse grid of them; the two images are the same in expectation); prints
# each's render time and time per sample of the image.
# DENSITY scales the densities (the medium's density_scale); OUT, when set, is a folder that keeps the two images.
#   N=128 SIZE=256 SPP=32 THREADS=2 DENSITY=1 bench/grid_medium.sh
set -euo pipefail
cd "$(dirname "$0")/.."
n=${N:-128}; size=${SIZE:-256}; spp=${SPP:-32}; threads=${THREADS:-$(nproc)}; density=${DENSITY:-1}
tessera=${TESSERA:-build/clients/cli/tessera}
/usr/bin/python3 -c 'import pyopenvdb' 2>/dev/null ||
  { echo "grid_medium: python3-openvdb is not installed (apt-get install python3-openvdb)" >&2; exit 2; }
[ -x "$tessera" ] || { echo "grid_medium: build tessera first (make build)" >&2; exit 2; }
work=$(mktemp -d); trap 'rm -rf "$work"' EXIT
/usr/bin/python3 bench/smoke_vdb.py "$work/smoke.vdb" "$n"
for majorant in global grid; do
  /usr/bin/python3 - "$size" "$spp" "$majorant" "$density" > "$work/job-$majorant.json" <<'PY'
import json, sys
size, spp, majorant, density = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3], float(sys.argv[4])
job = json.load(open("examples/smoke/smoke.json"))
job["scene"]["objects"][0]["medium"].update({"majorant": majorant, "density_scale": density})
job["render"].update({"width": size, "height": size, "spp": spp})
print(json.dumps(job))
PY
  out=$("$tessera" render "$work/job-$majorant.json" -o "$work/$majorant.exr" --threads "$threads" 2>&1) ||
    { echo "$out" >&2; exit 1; }
  t=$(echo "$out" | sed -n 's/.* spp in \([0-9.]*\)s.*/\1/p')
  /usr/bin/python3 -c "import sys; t, spp, size = float(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]); \
print(f'smoke grid {sys.argv[4]}^3 x {sys.argv[6]}, {size}x{size}, {spp} spp, majorant {sys.argv[5]}: {t:.2f} s, ' \
      f'{t / spp * 1000:.1f} ms per sample of the image')" "$t" "$spp" "$size" "$n" "$majorant" "$density"
  if [ -n "${OUT:-}" ]; then mkdir -p "$OUT"; cp "$work/$majorant.exr" "$OUT/"; fi
done
