#!/usr/bin/env bash
# tessera against Blender's Cycles (Debian's blender, CPU, Embree) on the same glTF scene: the Cornell box written as
# glTF (bench/cornell_to_gltf.py), same resolution, samples per pixel, maximum bounces, box pixel filter, no
# denoising, no adaptive sampling; render time only (Cycles: N samples minus 1 sample, so import, sync, kernel
# loading and BVH build are left out; tessera: its own render time, without loading).
#
# Error is measured against one neutral reference: the mean of a tessera and a Cycles render at REF_SPP (other seeds
# than the timed renders). The two references' own RMSE is printed too: it is how far apart the two renderers'
# converged images are (different material models: glTF PBR in tessera, the Principled BSDF in Cycles), a floor
# under both renderers' RMSE that more samples cannot remove.
#   SIZE=256 SPP=64 BOUNCES=8 REF_SPP=1024 bench/cycles_compare.sh   (needs: apt-get install blender python3-numpy)
set -euo pipefail
cd "$(dirname "$0")/.."
size=${SIZE:-256}; spp=${SPP:-64}; bounces=${BOUNCES:-8}; ref_spp=${REF_SPP:-1024}
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
cycles() {  # cycles OUT.exr SPP SEED -> prints the render seconds
  local out
  out=$(blender -b --factory-startup --python bench/cycles_render.py -- "$work/cornell.gltf" "$1" \
          "$size" "$size" "$2" "$bounces" "$threads" "$3" 2>&1)
  local t
  t=$(echo "$out" | sed -n 's/^CYCLES_RENDER_SECONDS //p')
  [ -n "$t" ] || { echo "$out" | tail -20 >&2; echo "cycles_compare: Cycles did not render" >&2; exit 1; }
  echo "$t"
}
secs() { sed -n 's/.* spp in \([0-9.]*\)s.*/\1/p'; }

job "$ref_spp" '{"seed": 99}' > "$work/ref.json"
job "$spp" > "$work/eq.json"
echo "references: tessera and Cycles, ${size}x${size}, $ref_spp spp each ..."
"$tessera" render "$work/ref.json" -o "$work/ref_tessera.exr" --threads "$threads" 2>&1 | tail -1
t_ref_cycles=$(cycles "$work/ref_cycles.exr" "$ref_spp" 99)
echo "Cycles: ${size}x${size}, $ref_spp spp in ${t_ref_cycles}s"

echo "timed renders: $spp spp ..."
t_tessera=$("$tessera" render "$work/eq.json" -o "$work/tessera.exr" --threads "$threads" 2>&1 | tail -1 | secs)
t_cycles=$(cycles "$work/cycles.exr" "$spp" 1)
# Equal time: tessera gets Cycles' render time.
job 65536 "{\"time_limit_s\": $t_cycles}" > "$work/eqtime.json"
"$tessera" render "$work/eqtime.json" -o "$work/tessera-eqtime.exr" --threads "$threads" 2>&1 | tail -1 > "$work/eqtime.log"

python3 - "$work" "$t_tessera" "$t_cycles" "$spp" "$size" <<'PY'
import re, subprocess, sys
work, tt, tc, spp, size = sys.argv[1], float(sys.argv[2]), float(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5])
def clamped(f):
    # Radiance clamped to [0, 1] (the displayable range) and RGB only: otherwise the light's edge pixels (radiance
    # 17) dominate every figure.
    subprocess.run(["oiiotool", f"{work}/{f}", "--ch", "R,G,B", "--clamp:min=0:max=1", "-o", f"{work}/c_{f}"], check=True)
    return f"{work}/c_{f}"
refs = [clamped("ref_tessera.exr"), clamped("ref_cycles.exr")]
subprocess.run(["oiiotool", refs[0], refs[1], "--add", "--mulc", "0.5", "-o", f"{work}/ref_mean.exr"], check=True)
def rmse(a, b):
    out = subprocess.run(["idiff", "-a", "-abs", a, b], capture_output=True, text=True).stdout
    m = re.search(r"RMS error = ([0-9.eE+-]+)", out)
    return float(m.group(1)) if m else float("nan")
ref = f"{work}/ref_mean.exr"
c_t, c_c = clamped("tessera.exr"), clamped("cycles.exr")
e_t, e_c = rmse(c_t, ref), rmse(c_c, ref)
e_tt = rmse(clamped("tessera-eqtime.exr"), ref)
m = re.search(r"(\d+) spp in", open(f"{work}/eqtime.log").read())
print(f"scene: Cornell box as glTF, {size}x{size}, {spp} spp, box filter, no denoising, no adaptive sampling")
print(f"references: RMSE between tessera's and Cycles' converged images {rmse(refs[0], refs[1]):.5f} "
      f"(the renderers' difference; each timed render is also scored against its own renderer's reference below)")
print(f"equal samples: tessera {tt:.2f} s, Cycles {tc:.2f} s  ->  tessera is {tc / tt:.2f}x as fast")
print(f"RMSE vs the mean reference at equal samples: tessera {e_t:.5f}, Cycles {e_c:.5f} (ratio {e_c / e_t:.2f})")
print(f"RMSE vs its own renderer's reference (noise only): tessera {rmse(c_t, refs[0]):.5f}, "
      f"Cycles {rmse(c_c, refs[1]):.5f}")
print(f"equal time ({tc:.2f} s): tessera {m.group(1) if m else '?'} spp, RMSE {e_tt:.5f} vs Cycles {e_c:.5f} "
      f"(ratio {e_c / e_tt:.2f})")
PY
