#!/usr/bin/env bash
# tessera against Blender's Cycles (Debian's blender, CPU, Embree) on the same glTF scene: the Cornell box written as
# glTF (bench/cornell_to_gltf.py), same resolution, samples per pixel, maximum bounces, box pixel filter, no
# denoising, no adaptive sampling; render time only (Cycles after a warm-up render; tessera's own render time,
# without loading). Both are compared by RMSE with one reference: tessera at REF_SPP.
#   SIZE=256 SPP=64 BOUNCES=8 bench/cycles_compare.sh     (needs: apt-get install blender python3-numpy)
set -euo pipefail
cd "$(dirname "$0")/.."
size=${SIZE:-256}; spp=${SPP:-64}; bounces=${BOUNCES:-8}; ref_spp=${REF_SPP:-4096}
threads=${THREADS:-$(nproc)}
tessera=${TESSERA:-build/clients/cli/tessera}
command -v blender >/dev/null || { echo "cycles_compare: blender is not installed (apt-get install blender python3-numpy)" >&2; exit 2; }
[ -x "$tessera" ] || { echo "cycles_compare: build tessera first (make build)" >&2; exit 2; }
work=$(mktemp -d); trap 'rm -rf "$work"' EXIT
python3 - "$size" > "$work/cornell-job.json" <<PY
import json, sys
j = json.load(open("proto/examples/cornell.json")); s = int(sys.argv[1])
j["render"].update({"width": s, "height": s}); print(json.dumps(j))
PY
python3 bench/cornell_to_gltf.py "$work/cornell-job.json" "$work/cornell.gltf"
job() {  # job SPP EXTRA_RENDER_JSON
  python3 -c "import json,sys; print(json.dumps({'kind':'scene','scene':{'gltf':'cornell.gltf','environment':{'color':0}},
    'render':dict({'width':$size,'height':$size,'spp':$1,'max_depth':$bounces,'seed':7}, **json.loads(sys.argv[1]))}))" "${2:-{\}}"
}
job "$ref_spp" '{"seed": 99}' > "$work/ref.json"
job "$spp" > "$work/eq.json"
echo "reference: tessera, ${size}x${size}, $ref_spp spp ..."
"$tessera" render "$work/ref.json" -o "$work/ref.exr" -q --threads "$threads" 2>&1 | tail -1
secs() { sed -n 's/.* spp in \([0-9.]*\)s.*/\1/p'; }
t_tessera=$("$tessera" render "$work/eq.json" -o "$work/tessera.exr" -q --threads "$threads" 2>&1 | tail -1 | secs)
out=$(blender -b --factory-startup --python bench/cycles_render.py -- "$work/cornell.gltf" "$work/cycles.exr" \
        "$size" "$size" "$spp" "$bounces" "$threads" 2>&1)
t_cycles=$(echo "$out" | sed -n 's/^CYCLES_RENDER_SECONDS //p')
[ -n "$t_cycles" ] || { echo "$out" | tail -20; echo "cycles_compare: Cycles did not render" >&2; exit 1; }
# Equal time: tessera gets Cycles' render time.
job 65536 "{\"time_limit_s\": $t_cycles}" > "$work/eqtime.json"
"$tessera" render "$work/eqtime.json" -o "$work/tessera-eqtime.exr" -q --threads "$threads" 2>&1 | tail -1 > "$work/eqtime.log"
python3 - "$work" "$t_tessera" "$t_cycles" "$spp" "$size" <<'PY'
import subprocess, sys, re
work, tt, tc, spp, size = sys.argv[1], float(sys.argv[2]), float(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5])
def rmse(a, b):
    # Radiance clamped to [0, 1] (the displayable range) and RGB only: otherwise the light's edge pixels (radiance
    # 17) dominate every figure.
    for f in (a, b):
        subprocess.run(["oiiotool", f"{work}/{f}", "--ch", "R,G,B", "--clamp:min=0:max=1", "-o", f"{work}/c_{f}"], check=True)
    out = subprocess.run(["idiff", "-a", "-abs", f"{work}/c_{a}", f"{work}/c_{b}"], capture_output=True, text=True).stdout
    m = re.search(r"RMS error = ([0-9.eE+-]+)", out)
    return float(m.group(1)) if m else float("nan")
eq_log = open(f"{work}/eqtime.log").read()
m = re.search(r"(\d+) spp in", eq_log)
print(f"scene: Cornell box as glTF, {size}x{size}, {spp} spp, box filter, no denoising, no adaptive sampling")
print(f"equal samples: tessera {tt:.2f} s, Cycles {tc:.2f} s  ->  tessera is {tc / tt:.2f}x as fast")
print(f"RMSE (radiance clamped to [0,1]) vs reference at equal samples: tessera {rmse('tessera.exr', 'ref.exr'):.5f}, Cycles {rmse('cycles.exr', 'ref.exr'):.5f}")
print(f"equal time ({tc:.2f} s): tessera {m.group(1) if m else '?'} spp, RMSE {rmse('tessera-eqtime.exr', 'ref.exr'):.5f}"
      f" vs Cycles {rmse('cycles.exr', 'ref.exr'):.5f}")
PY
