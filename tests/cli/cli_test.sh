#!/usr/bin/env bash
# The command line, for real: `tessera render` of sample ranges (and regions) merged with `tessera merge` equals one
# render bit for bit; bad input and bad usage exit 1 and 2; tessera links no renderer and runs tessera-render for
# those two commands; the daemon commands (tessera submit/watch/fetch/list/cancel and clients/curl/*.sh) against a
# real tesserad on a free port with a temporary data directory.
# usage: cli_test.sh TESSERA TESSERAD     (run by CTest)
set -uo pipefail
TESSERA=${1:?usage: cli_test.sh TESSERA TESSERAD}
TESSERAD=${2:?usage: cli_test.sh TESSERA TESSERAD}
repo=$(cd "$(dirname "$0")/../.." && pwd)
curl_dir=$repo/clients/curl
job=$repo/proto/examples/cornell.json
tmp=$(mktemp -d)
daemon_pid=""
cleanup() {
  if [[ -n $daemon_pid ]]; then kill -TERM "$daemon_pid" 2>/dev/null; wait "$daemon_pid" 2>/dev/null; fi
  rm -rf "$tmp"
}
trap cleanup EXIT
passed=0
failed=0
ok() { echo "ok - $1"; passed=$((passed + 1)); }
not_ok() { echo "not ok - $1"; failed=$((failed + 1)); }
# expect CODE NAME COMMAND...: the command exits with CODE.
expect() {
  local want=$1 name=$2
  shift 2
  "$@" >"$tmp/out" 2>"$tmp/err"
  local got=$?
  if [[ $got == "$want" ]]; then ok "$name"; else
    not_ok "$name (exit $got, expected $want)"
    sed 's/^/    /' "$tmp/out" "$tmp/err" | tail -20
  fi
}
png_signature() { [[ $(head -c 8 "$1" | od -An -tx1 | tr -d ' \n') == 89504e470d0a1a0a ]]; }
# The header and the fixed-point radiance sums of a .tfilm (renderer/film_codec.h: a 96-byte header, one 40-byte
# layer entry, then the 3 × 128-bit sums per pixel), all but the checksum at bytes 88..96, which covers the float
# luminance sums for the noise estimate that follow (those are not order-independent).
sums=$((96 + 40 + 48 * 40 * 32))
same_sums() { cmp -s -n 88 "$1" "$2" && cmp -s -i 96 -n $((sums - 96)) "$1" "$2"; }
same_pixels() { idiff -fail 0 -failpercent 0 -warn 0 "$1" "$2" >/dev/null 2>&1; }
# wait_for_samples ID: until the job has rendered a pass (at most 30 s).
wait_for_samples() {
  for _ in $(seq 300); do
    curl -sf "$TESSERA_URL/v1/jobs/$1" | python3 -c 'import json, sys; sys.exit(json.load(sys.stdin)["progress"]["samples_done"] == 0)' \
      && return
    sleep 0.1
  done
  not_ok "job $1 rendered no pass in 30 s"
}
cd "$tmp"

# --- sample ranges and regions merge into exactly one render -----------------------------------------------------
r=(--width 40 --height 32 --threads 2 -q)
# The slices are of a job of 12 samples per pixel (its render.spp, the budget a merge must cover).
job12=$tmp/cornell12.json
python3 -c 'import json, sys; d = json.load(open(sys.argv[1])); d["render"]["spp"] = 12; json.dump(d, open(sys.argv[2], "w"))' \
  "$job" "$job12"
expect 0 "render all 12 samples" "$TESSERA" render "$job" "${r[@]}" --spp 12 -o all.exr -o all.png -o all.tfilm
expect 0 "render samples 5:7" "$TESSERA" render "$job12" "${r[@]}" --samples 5:7 --integrator path -o b.tfilm
expect 0 "render with bdpt" "$TESSERA" render "$job" "${r[@]}" --spp 2 --integrator bdpt -o bdpt.png
expect 0 "render with light tracing" "$TESSERA" render "$job" "${r[@]}" --spp 2 --integrator light -o light.png
expect 0 "render samples 0:5 of the top half" "$TESSERA" render "$job12" "${r[@]}" --samples 0:5 --region 0,0,40,16 -o a1.tfilm
expect 0 "render samples 0:5 of the bottom half" "$TESSERA" render "$job12" "${r[@]}" --samples 0:5 --region 0,16,40,16 -o a2.tfilm
expect 0 "merge three parts out of order" "$TESSERA" merge b.tfilm a2.tfilm a1.tfilm -o merged.exr -o merged.png -o merged.tfilm
if same_sums merged.tfilm all.tfilm; then ok "the merged film has the single render's header and radiance sums, bit for bit"; else not_ok "merged film differs"; fi
if same_pixels merged.exr all.exr; then ok "the merged EXR has the single render's pixels"; else not_ok "merged EXR differs"; fi
if cmp -s merged.png all.png; then ok "the merged PNG equals the single render's PNG"; else not_ok "merged PNG differs"; fi
expect 0 "render samples 0:5 whole" "$TESSERA" render "$job12" "${r[@]}" --samples 0:5 -o a.tfilm
expect 0 "merge two ranges" "$TESSERA" merge a.tfilm b.tfilm -o two.tfilm
if same_sums two.tfilm all.tfilm; then ok "two ranges merge into the single render"; else not_ok "two ranges differ"; fi
expect 0 "a merged film merges again (nothing to add: one part)" "$TESSERA" merge two.tfilm -o again.tfilm
# Adaptive sampling: each slice decides from its own samples; the merge keeps every pixel's own count (the light,
# without variance, and its neighbours stop early), the same bits in either order.
adaptive=(--adaptive-threshold 0.05 --min-spp 2)
expect 0 "render adaptive samples 0:6" "$TESSERA" render "$job12" "${r[@]}" --samples 0:6 "${adaptive[@]}" -o c.tfilm
expect 0 "render adaptive samples 6:6" "$TESSERA" render "$job12" "${r[@]}" --samples 6:6 "${adaptive[@]}" -o d.tfilm
expect 0 "merge adaptive slices" "$TESSERA" merge c.tfilm d.tfilm -o cd.exr -o cd.tfilm
expect 0 "merge adaptive slices the other way" "$TESSERA" merge d.tfilm c.tfilm -o dc.exr -o dc.tfilm
if cmp -s cd.exr dc.exr && cmp -s -n 88 cd.tfilm dc.tfilm && cmp -s -i 96 -n $((sums - 96)) cd.tfilm dc.tfilm; then
  ok "adaptive slices merge to the same bits in either order"
else not_ok "adaptive slices merged in two orders differ"; fi
# The per-pixel counts, the film file's last 4 bytes a pixel: not all the range's 12 where pixels stopped.
counts=$(tail -c $((40 * 32 * 4)) cd.tfilm | od -An -tu4 -v | tr -s ' ' '\n' | sort -un | tr '\n' ' ')
if [[ $counts != " 12 " && $counts != "12 " ]]; then ok "the merged film keeps each pixel's count ($counts)"; else
  not_ok "every pixel of the merged adaptive film counts 12 samples"; fi
if same_sums again.tfilm all.tfilm; then ok "a merge of one part is that part"; else not_ok "re-merge differs"; fi

# --- render passes: layers of the EXR, every one of a merge bit for bit the single render's ---------------------------
aovs=(--aov variance --aov albedo --aov depth --aov object_id --aov sample_count)
expect 0 "render all 12 samples with passes" "$TESSERA" render "$job" "${r[@]}" --spp 12 "${aovs[@]}" -o aovs.exr
channels=$(oiiotool --info -v aovs.exr 2>/dev/null | grep 'channel list')
missing=""
for c in R G B albedo.R albedo.G albedo.B depth.Z object_id.X sample_count.X variance.R variance.B; do
  grep -qE "(^|[ ,:])$c \(" <<<"$channels" || missing+=" $c"
done
if [[ -z $missing ]]; then ok "the EXR names the beauty R, G, B and each pass <pass>.<channel>"; else
  not_ok "the EXR lacks$missing: $channels"
fi
expect 0 "render samples 0:5 with passes" "$TESSERA" render "$job12" "${r[@]}" --samples 0:5 "${aovs[@]}" -o p1.tfilm
expect 0 "render samples 5:7 with passes" "$TESSERA" render "$job12" "${r[@]}" --samples 5:7 "${aovs[@]}" -o p2.tfilm
expect 0 "merge the parts with passes" "$TESSERA" merge p2.tfilm p1.tfilm -o aovs_merged.exr
if cmp -s aovs_merged.exr aovs.exr; then ok "the merged EXR with passes is the single render's, byte for byte"; else not_ok "merged passes differ"; fi
expect 1 "parts with and without passes do not merge" "$TESSERA" merge p1.tfilm b.tfilm -o x.exr
expect 2 "a misspelt --aov is usage" "$TESSERA" render "$job" "${r[@]}" --spp 1 --aov depth --aov albdo -o x.exr
grep -qF -- '--aov albdo: must be one of' "$tmp/err" && grep -qF 'did you mean "albedo"' "$tmp/err" \
  && ok "render names the misspelt --aov and suggests albedo" || not_ok "render --aov albdo said: $(cat "$tmp/err")"
expect 2 "a pass the integrator cannot make is usage" "$TESSERA" render "$job" "${r[@]}" --spp 1 --integrator light --aov normal -o x.exr

# --- the denoiser: the beauty denoised, the rendered one kept as the layer noisy, the features only where asked ------
expect 0 "render denoised" "$TESSERA" render "$job" "${r[@]}" --spp 12 --aov normal --denoise regression -o dn.exr
channels=$(oiiotool --info -v dn.exr 2>/dev/null | grep 'channel list')
if [[ $channels == *"channel list: R, G, B, noisy.R, noisy.G, noisy.B, normal.X, normal.Y, normal.Z" ]]; then
  ok "the denoised EXR holds the beauty, noisy and the asked pass alone"
else
  not_ok "the denoised EXR's channels: $channels"
fi
oiiotool dn.exr --ch noisy.R,noisy.G,noisy.B --chnames R,G,B -o dn_noisy.exr
expect 0 "render the same without the denoiser" "$TESSERA" render "$job" "${r[@]}" --spp 12 --aov normal -o plain.exr
oiiotool plain.exr --ch R,G,B -o plain_beauty.exr
if same_pixels dn_noisy.exr plain_beauty.exr; then ok "noisy is the beauty as rendered"; else not_ok "noisy differs"; fi
expect 0 "render samples 0:5 denoised" "$TESSERA" render "$job12" "${r[@]}" --samples 0:5 --denoise regression -o d1.tfilm
expect 0 "render samples 5:7 denoised" "$TESSERA" render "$job12" "${r[@]}" --samples 5:7 --denoise regression -o d2.tfilm
expect 0 "merge the denoised parts" "$TESSERA" merge d2.tfilm d1.tfilm -o dn_merged.exr
oiiotool dn_merged.exr --ch R,G,B -o dn_merged_beauty.exr
oiiotool dn.exr --ch R,G,B -o dn_beauty.exr
if same_pixels dn_merged_beauty.exr dn_beauty.exr; then ok "a merge of denoised parts is denoised as the single render";
else not_ok "the merged denoised beauty differs"; fi
expect 2 "an unknown denoiser is usage" "$TESSERA" render "$job" "${r[@]}" --spp 1 --denoise nfor -o x.exr
grep -qF -- '--denoise nfor: must be' "$tmp/err" && ok "render names the unknown --denoise" \
  || not_ok "render --denoise nfor said: $(cat "$tmp/err")"

# --- assets resolve beside the job file, also when it is named relative to the current directory -------------------
mkdir -p assets
cp all.exr assets/sky.exr
echo '{"objects": [{"shape": "sphere", "center": [0, 0, 0], "radius": 1, "material": "m"}],
       "materials": {"m": {"type": "lambert", "albedo": 0.5}}, "environment": {"map": "sky.exr"},
       "camera": {"from": [0, 0, 4], "to": [0, 0, 0]}}' >assets/job.json
(cd assets && expect 0 "a job file named relative to the current directory finds its asset" "$TESSERA" render job.json \
  --width 16 --height 16 --spp 1 --threads 2 -q -o ../rel.png)
png_signature rel.png && ok "the relative job rendered a PNG" || not_ok "no PNG from the relative job"

# --- a glTF asset renders directly, as the job that names it would ---------------------------------------------------
python3 - <<'PY'
import base64, json, struct
pos = struct.pack("<9f", -1, -1, 0, 1, -1, 0, 0, 1, 0)
gltf = {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0, 1]}],
        "nodes": [{"mesh": 0}, {"camera": 0, "translation": [0, 0, 3]}],
        "cameras": [{"type": "perspective", "perspective": {"yfov": 0.8, "znear": 0.1}}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "material": 0}]}],
        "materials": [{"emissiveFactor": [1, 0.5, 0.25]}],
        "buffers": [{"byteLength": len(pos), "uri": "data:application/octet-stream;base64," + base64.b64encode(pos).decode()}],
        "bufferViews": [{"buffer": 0, "byteLength": len(pos)}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                       "min": [-1, -1, 0], "max": [1, 1, 0]}]}
json.dump(gltf, open("assets/tri.gltf", "w"))
json.dump({"kind": "scene", "scene": {"gltf": "tri.gltf"}}, open("assets/tri-job.json", "w"))
gltf["extensionsUsed"] = ["EXT_unknown_thing"]
json.dump(gltf, open("assets/tri-ext.gltf", "w"))
PY
expect 0 "tessera render of a .gltf" "$TESSERA" render assets/tri.gltf --width 16 --height 16 --spp 2 --threads 2 -q -o tri.exr
expect 0 "tessera render of the job naming it" "$TESSERA" render assets/tri-job.json --width 16 --height 16 --spp 2 \
  --threads 2 -q -o tri-job.exr
if same_pixels tri.exr tri-job.exr; then ok "the asset rendered as its job does"; else not_ok "the asset and its job differ"; fi
# The scene's warnings reach the user of tessera render (as they reach a daemon job's status), even with -q.
expect 0 "tessera render of a .gltf with an unsupported extension" "$TESSERA" render assets/tri-ext.gltf --width 16 \
  --height 16 --spp 1 --threads 2 -q -o tri-ext.exr
if grep -q "warning: extension EXT_unknown_thing is not supported" "$tmp/err"; then
  ok "tessera render prints the scene's warnings"
else
  not_ok "tessera render printed no warning for EXT_unknown_thing: $(cat "$tmp/err")"
fi
# The centre pixel sees the emissive triangle through the asset's camera: its emission (1, 0.5, 0.25) plus the grey
# default sky reflected by its white base colour, so the channels differ by the emission's differences.
centre=$(oiiotool tri.exr --cut 1x1+8+8 --printstats 2>/dev/null | awk '/Stats Avg/ {print $3, $4, $5}')
if awk -v c="$centre" 'BEGIN { split(c, v, " "); d1 = v[1] - v[2] - 0.5; d2 = v[2] - v[3] - 0.25;
                               exit !(v[1] >= 1 && d1 * d1 < 1e-6 && d2 * d2 < 1e-6) }'; then
  ok "the asset rendered its own camera and emissive triangle"
else
  not_ok "the centre pixel of the asset is '$centre', not its emission (1, 0.5, 0.25) over a grey reflection"
fi
# --time and --animation (scene.time, scene.animation): an asset without animations renders the same at any time; an
# animation that moves the triangle out of view does so at its time; one the asset does not have is refused.
expect 0 "tessera render --time of an asset without animations" "$TESSERA" render assets/tri.gltf --width 16 \
  --height 16 --spp 2 --threads 2 -q -o tri-t0.exr --time 0
if same_pixels tri.exr tri-t0.exr; then ok "--time 0 renders an asset without animations unchanged"; else
  not_ok "--time 0 changed the render of an asset without animations"
fi
python3 - <<'PY'
import base64, json, struct
gltf = json.load(open("assets/tri.gltf"))
raw = base64.b64decode(gltf["buffers"][0]["uri"].split(",")[1])
keys = struct.pack("<2f", 0, 1) + struct.pack("<6f", 0, 0, 0, 100, 0, 0)
gltf["buffers"][0] = {"byteLength": len(raw) + len(keys),
                      "uri": "data:application/octet-stream;base64," + base64.b64encode(raw + keys).decode()}
gltf["bufferViews"] += [{"buffer": 0, "byteOffset": len(raw), "byteLength": 8},
                        {"buffer": 0, "byteOffset": len(raw) + 8, "byteLength": 24}]
gltf["accessors"] += [{"bufferView": 1, "componentType": 5126, "count": 2, "type": "SCALAR", "min": [0], "max": [1]},
                      {"bufferView": 2, "componentType": 5126, "count": 2, "type": "VEC3",
                       "min": [0, 0, 0], "max": [100, 0, 0]}]
gltf["animations"] = [{"name": "away", "samplers": [{"input": 1, "output": 2}],
                       "channels": [{"sampler": 0, "target": {"node": 0, "path": "translation"}}]}]
json.dump(gltf, open("assets/tri-anim.gltf", "w"))
PY
expect 0 "tessera render --time 1 --animation away" "$TESSERA" render assets/tri-anim.gltf --width 16 --height 16 \
  --spp 2 --threads 2 -q -o tri-away.exr --time 1 --animation away
if same_pixels tri.exr tri-away.exr; then not_ok "--time 1 did not move the animated triangle"; else
  ok "--time 1 renders the animated triangle moved away"
fi
expect 0 "tessera render --animation 0 (an index) at 0 s" "$TESSERA" render assets/tri-anim.gltf --width 16 \
  --height 16 --spp 2 --threads 2 -q -o tri-anim0.exr --animation 0
if same_pixels tri.exr tri-anim0.exr; then ok "at 0 s the animated triangle is where it starts"; else
  not_ok "--animation 0 at 0 s moved the triangle"
fi
expect 1 "tessera render --animation of an animation the asset lacks" "$TESSERA" render assets/tri-anim.gltf \
  --width 16 --height 16 --spp 1 --threads 2 -q -o x.exr --animation awya
grep -qF 'at /scene/animation: the glTF asset has no animation "awya" (did you mean "away"?)' "$tmp/err" \
  && ok "the refusal names /scene/animation and the closest name" || not_ok "--animation awya said: $(cat "$tmp/err")"

# --frames (render.frames): frame f is the still at f / 24 s, byte for byte, in numbered files; bad ranges are usage
# errors naming the option; an output in a frame's way is refused before anything renders.
expect 0 "tessera render --frames 0-24:12" "$TESSERA" render assets/tri-anim.gltf --width 16 --height 16 --spp 2 \
  --threads 2 -q -o tri-f.exr --frames 0-24:12 --animation away
if [[ -f tri-f.0000.exr && -f tri-f.0012.exr && -f tri-f.0024.exr && ! -e tri-f.exr ]]; then
  ok "--frames 0-24:12 writes tri-f.0000.exr, tri-f.0012.exr and tri-f.0024.exr"
else not_ok "--frames 0-24:12 wrote: $(ls tri-f*)"; fi
cmp -s tri-f.0024.exr tri-away.exr && ok "frame 24 is the still at 1 s, byte for byte" \
  || not_ok "frame 24 differs from the still at --time 1"
cmp -s tri-f.0000.exr tri-anim0.exr && ok "frame 0 is the still at 0 s, byte for byte" \
  || not_ok "frame 0 differs from the still at 0 s"
expect 2 "tessera render --frames 5-1" "$TESSERA" render assets/tri-anim.gltf -q -o x.exr --frames 5-1
grep -qF -- "--frames 5-1: must not be before start (5)" "$tmp/err" && ok "the refusal names --frames" \
  || not_ok "--frames 5-1 said: $(cat "$tmp/err")"
expect 2 "tessera render --frames 1-x" "$TESSERA" render assets/tri-anim.gltf -q -o x.exr --frames 1-x
expect 2 "tessera render --frames of an asset without animations" "$TESSERA" render assets/tri.gltf -q -o x.exr \
  --frames 1-2
grep -qF "no animations" "$tmp/err" && ok "the refusal says the asset has no animations" \
  || not_ok "--frames of tri.gltf said: $(cat "$tmp/err")"
# --shutter (render.shutter): a frame blurred over its shutter is the still at its time with the same shutter, byte for
# byte, and differs from the frame without one; a bad shutter is a usage error naming the option. The triangle is
# made grey under a white sky (an emissive mesh is not blurred).
python3 - <<'PY'
import json
gltf = json.load(open("assets/tri-anim.gltf"))
gltf["materials"] = [{"pbrMetallicRoughness": {"baseColorFactor": [0.2, 0.2, 0.2, 1], "metallicFactor": 0}}]
json.dump(gltf, open("assets/tri-grey.gltf", "w"))
json.dump({"kind": "scene", "scene": {"gltf": "tri-grey.gltf", "environment": {"color": [1, 1, 1]}}},
          open("assets/tri-grey-job.json", "w"))
PY
for shutter in "" "--shutter 0:1:4"; do
  out=tri-grey${shutter:+-mb}.exr
  # shellcheck disable=SC2086
  expect 0 "tessera render --frames 0-0 $shutter" "$TESSERA" render assets/tri-grey-job.json --width 16 --height 16 \
    --spp 2 --threads 2 -q -o "$out" --frames 0-0 $shutter
done
expect 0 "tessera render --time 0 --shutter 0:1:4" "$TESSERA" render assets/tri-grey-job.json --width 16 \
  --height 16 --spp 2 --threads 2 -q -o tri-grey-mb-still.exr --time 0 --shutter 0:1:4
cmp -s tri-grey-mb.0000.exr tri-grey-mb-still.exr && ok "a blurred frame is the blurred still at its time, byte for byte" \
  || not_ok "frame 0 with --shutter differs from the still at 0 s with it"
if same_pixels tri-grey-mb.0000.exr tri-grey.0000.exr; then not_ok "--shutter did not blur the moving triangle"; else
  ok "--shutter blurs the moving triangle"
fi
expect 2 "tessera render --shutter 0.25:-0.25" "$TESSERA" render assets/tri-anim.gltf -q -o x.exr --time 0 \
  --shutter 0.25:-0.25
grep -qF -- "--shutter 0.25:-0.25: must not be before open (0.25)" "$tmp/err" && ok "the refusal names --shutter" \
  || not_ok "--shutter 0.25:-0.25 said: $(cat "$tmp/err")"
expect 2 "tessera render --shutter 0.25" "$TESSERA" render assets/tri-anim.gltf -q -o x.exr --shutter 0.25
mkdir -p blocked.0002.png
expect 1 "a frame's output in the way is refused before rendering" "$TESSERA" render assets/tri-anim.gltf \
  --width 16 --height 16 --spp 1 --threads 2 -q -o blocked.png --frames 1-3
grep -qF "blocked.0002.png: it is a directory" "$tmp/err" && [[ ! -e blocked.0001.png ]] \
  && ok "the refusal names frame 2's file, and frame 1 was not rendered" || not_ok "blocked said: $(cat "$tmp/err")"

# --- refused merges and bad input: fatal (1) ---------------------------------------------------------------------
expect 1 "overlapping ranges are refused" "$TESSERA" merge a.tfilm all.tfilm -o x.exr
grep -q "overlapping" "$tmp/err" && ok "the refusal says the parts overlap" || not_ok "no overlap message"
expect 1 "a gap is refused" "$TESSERA" merge a1.tfilm b.tfilm -o x.exr
# The parts must cover the job's whole budget: a slice lost at either end is named, and refused unless allowed.
expect 1 "parts missing the end of the budget are refused" "$TESSERA" merge a.tfilm -o x.exr
grep -qF "samples 5..12 are missing" "$tmp/err" && ok "the refusal names the missing end" || not_ok "no missing end: $(cat "$tmp/err")"
expect 1 "parts missing the start of the budget are refused" "$TESSERA" merge b.tfilm -o x.exr
grep -qF "samples 0..5 are missing" "$tmp/err" && ok "the refusal names the missing start" || not_ok "no missing start: $(cat "$tmp/err")"
grep -qF -- "--allow-partial" "$tmp/err" && ok "the refusal says how to merge anyway" || not_ok "no --allow-partial hint"
expect 0 "--allow-partial merges what there is" "$TESSERA" merge b.tfilm --allow-partial -o partial.exr -o partial.tfilm
expect 1 "a merge of a partial merge is still partial" "$TESSERA" merge partial.tfilm -o x.exr
"$TESSERA" render "$job12" "${r[@]}" --samples 0:5 --time-limit 0.000001 -o cut.tfilm 2>/dev/null
expect 1 "a slice a time limit cut short leaves a gap" "$TESSERA" merge cut.tfilm b.tfilm -o x.exr
"$TESSERA" render "$job" "${r[@]}" --samples 0:5 -o of256.tfilm 2>/dev/null
expect 1 "slices of jobs of different budgets are refused" "$TESSERA" merge of256.tfilm b.tfilm -o x.exr
grep -qE "(256 and 12|12 and 256) samples per pixel" "$tmp/err" && ok "the refusal names both budgets" || not_ok "no budgets: $(cat "$tmp/err")"
"$TESSERA" render "$job12" "${r[@]}" --samples 0:5 --seed 7 -o other-seed.tfilm 2>/dev/null
expect 1 "parts of different settings are refused" "$TESSERA" merge other-seed.tfilm b.tfilm -o x.exr
grep -q "fingerprint" "$tmp/err" && ok "the refusal names the fingerprint" || not_ok "no fingerprint message"
"$TESSERA" render "$job" --width 20 --height 32 --threads 2 -q --samples 0:5 -o small.tfilm 2>/dev/null
expect 1 "parts of different sizes are refused" "$TESSERA" merge small.tfilm b.tfilm -o x.exr
head -c 100 all.tfilm >truncated.tfilm
expect 1 "a truncated film is refused" "$TESSERA" merge truncated.tfilm -o x.exr
# A region whose right edge is past 2^31 (x + width overflows an int) is outside the image, not a region it wraps
# into (found by tests/fuzz's fuzz_tfilm: the header's x and width at offsets 28 and 36).
python3 -c 'import struct, sys; b = bytearray(open(sys.argv[1], "rb").read()); b[28:32] = struct.pack("<i", 2**31 - 100)
b[36:40] = struct.pack("<i", 200); open(sys.argv[2], "wb").write(b)' a.tfilm far.tfilm
expect 1 "a region past the largest integer is refused" "$TESSERA" merge far.tfilm -o x.exr
grep -q "region outside the image" "$tmp/err" && ok "the refusal says the region is outside" || not_ok "no region message"
echo "not a film" >junk.tfilm
expect 1 "a file that is not a film is refused" "$TESSERA" merge junk.tfilm -o x.exr
expect 1 "a missing job file is fatal" "$TESSERA" render "$tmp/none.json" -o x.png
echo '{"kind": "scene", "scene": {"objects": [' >broken.json
expect 1 "a job that is not JSON is fatal" "$TESSERA" render broken.json -o x.png
echo '{"kind": "scene", "scene": {"objects": [{"shape": "sphere", "center": [0,0,0], "radius": 1, "material": "nope"}]}}' >bad.json
expect 1 "a job naming an unknown material is fatal" "$TESSERA" render bad.json -o x.png
# The daemon's schemas, with its messages: an unknown property is refused, not rendered with the default.
echo '{"kind": "scene", "scene": {"objects": [{"shape": "sphere", "center": [0,0,0], "radius": 1, "material": "m"}],
       "materials": {"m": {"type": "lambert", "albdo": 0.5}}, "camera": {"from": [0, 0, 4], "to": [0, 0, 0]}}}' >albdo.json
expect 1 "render refuses an unknown material property" "$TESSERA" render albdo.json -o x.png -q
grep -qF 'albdo.json: at /scene/materials/m/albdo: unknown property "albdo"' "$tmp/err" \
  && ok "render names the property and its pointer" || not_ok "render said: $(cat "$tmp/err")"
cp "$tmp/err" render-albdo.err
python3 - "$job" spp_.json <<'PY'
import json, sys
j = json.load(open(sys.argv[1]))
j["render"]["spp_"] = 4
json.dump(j, open(sys.argv[2], "w"))
PY
expect 1 "render refuses \"spp_\"" "$TESSERA" render spp_.json -o x.png -q
grep -qF 'at /render/spp_: unknown property "spp_"' "$tmp/err" && ok "render names spp_" || not_ok "render said: $(cat "$tmp/err")"
echo '{"objects": [{"shape": "sphere", "center": [0,0,0], "radius": -1, "material": "m"}],
       "materials": {"m": {"type": "lambert"}}, "camera": {"from": [0, 0, 4], "to": [0, 0, 0]}}' >bare.json
expect 1 "render refuses a bad bare scene" "$TESSERA" render bare.json -o x.png -q
grep -qF 'bare.json: at /objects/0/radius: must be greater than 0' "$tmp/err" \
  && ok "a bare scene's error points into the file as written" || not_ok "render said: $(cat "$tmp/err")"
# Outputs are checked before anything is rendered: a path that cannot be written is bad input (1), said at once.
expect 1 "an output in a missing directory is refused before rendering" "$TESSERA" render "$job" "${r[@]}" --spp 4 \
  -o first.png -o /nonexistent/out.png
if grep -qF "cannot write /nonexistent/out.png: there is no directory /nonexistent" "$tmp/err" \
  && ! grep -qF " spp in " "$tmp/err" && [[ ! -e first.png ]]; then
  ok "the refusal names the missing directory, and nothing was rendered or written"
else
  not_ok "render of an unwritable output said: $(cat "$tmp/err")"
fi
mkdir -p dir.png
expect 1 "an output that is a directory is refused" "$TESSERA" render "$job" "${r[@]}" --spp 1 -o dir.png
grep -qF "cannot write dir.png: it is a directory" "$tmp/err" && ok "the refusal says it is a directory" \
  || not_ok "render said: $(cat "$tmp/err")"
expect 1 "an output below a file is refused" "$TESSERA" render "$job" "${r[@]}" --spp 1 -o all.png/x.exr
grep -qF "all.png is not a directory" "$tmp/err" && ok "the refusal says all.png is not a directory" \
  || not_ok "render said: $(cat "$tmp/err")"
expect 1 "merge refuses an unwritable output" "$TESSERA" merge a.tfilm b.tfilm -o /nonexistent/merged.exr
# Messages that help: every schema error at once, integer limits as integers, the closest known name.
echo '{"kind": "scene", "render": {"spp": 0, "width": 1.5},
       "scene": {"objects": [{"shape": "sphere", "center": [0,0,0], "radius": 1, "material": "m"}],
                 "materials": {"m": {"type": "lambert", "albdo": 0.5}, "n": {"type": "lamber"}},
                 "camera": {"from": [0, 0, 4], "to": [0, 0, 0]}}}' >many.json
expect 1 "render refuses a job with four errors" "$TESSERA" render many.json -o x.png -q
cp "$tmp/err" render-many.err
for line in 'at /render/spp: must be at least 1' 'at /render/width: must be an integer' \
  'at /scene/materials/m/albdo: unknown property "albdo" (did you mean "albedo"?)' \
  'at /scene/materials/n/type: must be one of "lambert", '; do
  grep -qF "many.json: $line" "$tmp/err" && ok "render says: $line" || not_ok "render did not say '$line': $(cat "$tmp/err")"
done
grep -qxF "tessera: many.json: more checks (material names, indices, assets, limits) follow once these errors are fixed" \
  "$tmp/err" && ok "render says that more checks follow" || not_ok "render of many.json said: $(cat "$tmp/err")"
grep -q 'at least 1\.0' "$tmp/err" && not_ok "an integer limit printed as a float" || ok "integer limits print as integers"
grep -qF '(did you mean "lambert"?)' "$tmp/err" && ok "an unknown material type suggests the closest" \
  || not_ok "no suggestion for lamber: $(cat "$tmp/err")"
echo '{"kind": "scene", "scene": {"objects": [{"shape": "sphere", "center": [0,0,0], "radius": 1, "material": "purple"}],
       "materials": {"m": {"type": "lambert", "albdo": 0.5}}, "camera": {"from": [0, 0, 4], "to": [0, 0, 0]}}}' >mixed.json
expect 1 "render refuses a misspelt property and an unknown material" "$TESSERA" render mixed.json -o x.png -q
grep -qF 'mixed.json: at /scene/materials/m/albdo: unknown property "albdo"' "$tmp/err" \
  && grep -qF 'mixed.json: at /scene/objects/0/material: unknown material "purple"' "$tmp/err" \
  && ok "render names the unknown material with the schema's error" || not_ok "render of mixed.json said: $(cat "$tmp/err")"
echo '{"kind": "scene", "scene": {"objects": [{"shape": "sphere", "center": [0,0,0], "radius": 1, "material": "mirror"}],
       "materials": {"mirorr": {"type": "conductor"}}, "camera": {"from": [0, 0, 4], "to": [0, 0, 0]}}}' >mirror.json
expect 1 "render refuses a misspelt material name" "$TESSERA" render mirror.json -o x.png -q
grep -qF 'unknown material "mirror" (did you mean "mirorr"?)' "$tmp/err" && ok "the material name is suggested" \
  || not_ok "render said: $(cat "$tmp/err")"
printf '{"kind": "scene",\n "render": {"spp": 4,}}\n' >comma.json
expect 1 "render of broken JSON is fatal" "$TESSERA" render comma.json -o x.png -q
grep -qF "comma.json is not valid JSON: parse error at line 2, column 22" "$tmp/err" && ok "render gives line and column" \
  || not_ok "render said: $(cat "$tmp/err")"
expect 1 "submit of broken JSON is fatal before any request" "$TESSERA" submit comma.json --url http://127.0.0.1:9
grep -qF "comma.json is not valid JSON: parse error at line 2, column 22" "$tmp/err" && ok "submit gives line and column" \
  || not_ok "submit said: $(cat "$tmp/err")"
# A file that is not a job says what it is (by its magic bytes) and what a job is.
cp all.png render.png
expect 1 "submit of a PNG is fatal before any request" "$TESSERA" submit render.png --url http://127.0.0.1:9
grep -qF "render.png is a PNG image, not a job: a job is a JSON document (.json), or a glTF scene (.glb or .gltf)" \
  "$tmp/err" && ok "submit says the file is a PNG image" || not_ok "submit of a PNG said: $(cat "$tmp/err")"
cp all.exr render.json
expect 1 "render of an EXR named .json is fatal" "$TESSERA" render render.json -o x.png -q
grep -qF "render.json is an OpenEXR image, not a job" "$tmp/err" && ok "render says the file is an EXR image" \
  || not_ok "render of an EXR said: $(cat "$tmp/err")"
# A .gltf whose buffer is not beside it: said by the command line, before anything is sent.
python3 - <<'PY'
import json
json.dump({"asset": {"version": "2.0"}, "buffers": [{"byteLength": 36, "uri": "Box0.bin"}]}, open("assets/Box.gltf", "w"))
PY
expect 1 "submit of a .gltf without its .bin is fatal before any request" "$TESSERA" submit assets/Box.gltf \
  --url http://127.0.0.1:9
grep -qF "Box0.bin not found beside assets/Box.gltf" "$tmp/err" && ok "submit names the missing buffer" \
  || not_ok "submit of a .gltf without its .bin said: $(cat "$tmp/err")"
# A render setting given as an option is the option's error (usage, 2), with the closest valid value.
expect 2 "an unknown --integrator is usage" "$TESSERA" render "$job" "${r[@]}" --spp 1 --integrator bpdt -o x.png
grep -qF -- '--integrator bpdt: must be one of "bdpt", "light" or "path" (did you mean "bdpt"?)' "$tmp/err" \
  && ok "render names --integrator and suggests bdpt" || not_ok "render --integrator bpdt said: $(cat "$tmp/err")"
grep -qF "/render/integrator" "$tmp/err" && not_ok "the option's error points into the job file" \
  || ok "the option's error does not point into the job file"
expect 2 "an unknown --integrator far from any is usage" "$TESSERA" render "$job" "${r[@]}" --integrator photon_mapping \
  -o x.png
expect 2 "--spp 0 is usage" "$TESSERA" render "$job" "${r[@]}" --spp 0 -o x.png
grep -qF -- "--spp 0: must be at least 1" "$tmp/err" && ok "render names --spp" || not_ok "render --spp 0 said: $(cat "$tmp/err")"
# -q prints nothing but errors: no progress, no summary.
expect 0 "render -q" "$TESSERA" render "$job" "${r[@]}" --spp 1 -o quiet.png
[[ ! -s $tmp/err && ! -s $tmp/out ]] && ok "render -q printed nothing" || not_ok "render -q printed: $(cat "$tmp/out" "$tmp/err")"
expect 0 "render without -q" "$TESSERA" render "$job" --width 40 --height 32 --threads 2 --spp 1 -o loud.png
grep -qF " spp in " "$tmp/err" && ok "render without -q prints its summary" || not_ok "no summary: $(cat "$tmp/err")"
expect 1 "a region outside the image is fatal" "$TESSERA" render "$job" "${r[@]}" --samples 0:1 --region 30,0,20,10 -o x.tfilm

# --- usage: 2 ----------------------------------------------------------------------------------------------------
expect 2 "no command" "$TESSERA"
expect 2 "an unknown command" "$TESSERA" frobnicate
expect 2 "render without outputs" "$TESSERA" render "$job"
expect 2 "an unknown option" "$TESSERA" render "$job" -o x.png --bogus
grep -q "did you mean" "$tmp/err" && not_ok "a far-off option got a suggestion: $(cat "$tmp/err")" \
  || ok "nothing is suggested for a name like no option"
expect 2 "a misspelt option" "$TESSERA" render "$job" -o x.png --widht 8
grep -qF 'unknown option --widht (did you mean "--width"?)' "$tmp/err" && ok "render suggests --width" \
  || not_ok "render said: $(cat "$tmp/err")"
expect 2 "a misspelt list option" "$TESSERA" list --stat running
grep -qF 'unknown option --stat (did you mean "--state"?)' "$tmp/err" && ok "list suggests --state" \
  || not_ok "list said: $(cat "$tmp/err")"
expect 2 "a misspelt command" "$TESSERA" sumbit x.json
grep -qF "unknown command 'sumbit' (did you mean \"submit\"?)" "$tmp/err" && ok "tessera suggests submit" \
  || not_ok "tessera said: $(cat "$tmp/err")"
expect 0 "tessera --version" "$TESSERA" --version
grep -qE '^tessera [0-9]+\.[0-9]+\.[0-9]+$' "$tmp/out" && ok "tessera prints its version" || not_ok "tessera --version: $(cat "$tmp/out")"
expect 0 "tesserad --version" "$TESSERAD" --version
grep -qE '^tesserad [0-9]+\.[0-9]+\.[0-9]+$' "$tmp/out" && ok "tesserad prints its version" \
  || not_ok "tesserad --version: $(cat "$tmp/out")"
expect 2 "a misspelt tesserad option" "$TESSERAD" --prot 8080
grep -qF 'unknown option --prot (did you mean "--port"?)' "$tmp/err" && ok "tesserad suggests --port" \
  || not_ok "tesserad said: $(cat "$tmp/err")"
expect 2 "a bad --samples" "$TESSERA" render "$job" -o x.png --samples 3
expect 2 "a bad --region" "$TESSERA" render "$job" -o x.png --region 1,2,3
expect 2 "an unknown output format" "$TESSERA" render "$job" -o x.gif
expect 2 "merge without outputs" "$TESSERA" merge a.tfilm
expect 2 "watch without an id" "$TESSERA" watch
for c in render merge submit watch fetch list cancel log; do expect 0 "tessera $c -h" "$TESSERA" "$c" -h; done
for s in submit watch fetch list cancel; do expect 0 "$s.sh -h" "$curl_dir/$s.sh" -h; done
expect 2 "submit.sh without arguments" "$curl_dir/submit.sh"

# --- two programs: tessera loads no renderer; render and merge run tessera-render from beside it --------------------
# (The renderer's image libraries take most of a second to load: a script that submits and polls should not pay it.)
needed=$(readelf -d "$TESSERA" | grep NEEDED)
if grep -qiE 'embree|OpenImageIO|tinygltf' <<<"$needed"; then not_ok "tessera links the renderer's libraries"; else
  ok "tessera links no renderer library"; fi
[[ -x $(dirname "$TESSERA")/tessera-render ]] && ok "tessera-render is beside tessera" || not_ok "no tessera-render"
mkdir -p alone && cp "$TESSERA" alone/tessera
expect 1 "render without tessera-render (not beside tessera, not on the PATH) is fatal" \
  env PATH="$tmp/alone" alone/tessera render "$job" -o x.png
grep -q "cannot run tessera-render" "$tmp/err" && ok "the message names tessera-render" || not_ok "message: $(cat "$tmp/err")"
mkdir -p onpath && ln -s "$(dirname "$TESSERA")/tessera-render" onpath/tessera-render
expect 0 "render with tessera-render found on the PATH" env PATH="$tmp/onpath" alone/tessera render "$job" \
  --width 8 --height 8 --spp 1 -q -o path.png
png_signature path.png && ok "that render wrote a PNG" || not_ok "that render wrote no PNG"
expect 0 "tessera-render -h" "$(dirname "$TESSERA")/tessera-render" -h
expect 2 "tessera-render without a command" "$(dirname "$TESSERA")/tessera-render"

# --- a daemon that is not there: retry (75) ----------------------------------------------------------------------
expect 75 "an unreachable daemon is transient" "$TESSERA" list --url http://127.0.0.1:9
grep -qF "is tesserad running? (\`make run\` in the repository starts it" "$tmp/err" && ok "tessera says how to start it" \
  || not_ok "tessera said: $(cat "$tmp/err")"
expect 2 "a --url that is not http is usage" "$TESSERA" list --url ftp://x

# --- against a real tesserad -------------------------------------------------------------------------------------
"$TESSERAD" --port 0 --listen 127.0.0.1 --data-dir "$tmp/data" --threads 2 --log-level warn >"$tmp/daemon.out" 2>"$tmp/daemon.err" &
daemon_pid=$!
url=""
for _ in $(seq 100); do
  url=$(sed -n 's/.*listening on \(http:[^ ]*\).*/\1/p' "$tmp/daemon.out" | head -1)
  [[ -n $url ]] && break
  sleep 0.1
done
if [[ -z $url ]]; then
  not_ok "tesserad did not start"; cat "$tmp/daemon.err"
else
  ok "tesserad listens on $url"
  export TESSERA_URL=$url
  python3 - "$job" small.json long.json <<'PY'
import json, sys
j = json.load(open(sys.argv[1]))
del j["name"]  # a job is called by its file unless it names itself
j["render"].update(width=32, height=32, spp=8)
json.dump(j, open(sys.argv[2], "w"))
j["render"].update(width=256, height=256, spp=65536)
json.dump(j, open(sys.argv[3], "w"))
PY
  expect 0 "tessera submit" "$TESSERA" submit small.json
  id=$(cat "$tmp/out")
  expect 0 "tessera watch follows it to success" "$TESSERA" watch "$id"
  grep -q succeeded "$tmp/out" && ok "watch printed the final state" || not_ok "watch printed no final state"
  expect 0 "tessera list" "$TESSERA" list
  head -1 "$tmp/out" | grep -qE '^ID +STATE +PRIO +SAMPLES +CREATED +NAME$' && ok "list has a header row" \
    || not_ok "list's first line: $(head -1 "$tmp/out")"
  grep -q "$id" "$tmp/out" && ok "list shows the job" || not_ok "list misses the job"
  grep "$id" "$tmp/out" | grep -q "small.json" && ok "list names the job after its file" ||
    not_ok "list gives no name: $(grep "$id" "$tmp/out")"
  expect 0 "tessera list --state succeeded --json" "$TESSERA" list --state succeeded --json
  expect 0 "tessera log" "$TESSERA" log "${id:0:8}"
  grep -q "succeeded: its samples-per-pixel budget was reached" "$tmp/out" && grep -q "pass 1: " "$tmp/out" &&
    ok "log tells the passes and why the render ended" || not_ok "tessera log printed: $(cat "$tmp/out")"
  # A job id may be shortened to the 8 digits the web client shows, or any start that only one job has.
  expect 0 "fetch by the 8-digit prefix of an id" "$TESSERA" fetch "${id:0:8}" -d by-prefix
  [[ -s by-prefix/$id.png ]] && ok "the prefix named the whole id" || not_ok "no by-prefix/$id.png"
  # Fewer than 4 digits name a job by chance: a usage error, for every command that takes an id, before any request.
  for c in watch fetch cancel log; do
    expect 2 "tessera $c refuses a one-digit id prefix" "$TESSERA" "$c" "${id:0:1}"
    grep -qF "\"${id:0:1}\" is too short for a job id: give at least 4 of its hex digits" "$tmp/err" \
      && ok "tessera $c names the 4-digit rule" || not_ok "tessera $c ${id:0:1} said: $(cat "$tmp/err")"
  done
  expect 2 "a three-digit prefix is usage" "$TESSERA" cancel "${id:0:3}"
  expect 0 "a four-digit prefix names the job" "$TESSERA" log "${id:0:4}"
  # An ambiguous prefix lists its candidates: two jobs of a stand-in daemon share 4 digits (random ids rarely do).
  mkdir -p fake/v1
  echo '{"jobs": [{"id": "abcd0000000000000000000000000001", "state": "succeeded", "name": "one"},
                  {"id": "abcd0000000000000000000000000002", "state": "queued", "name": "two"}]}' >fake/v1/jobs
  python3 -u -m http.server 0 --bind 127.0.0.1 --directory fake >fake.out 2>&1 &
  fake_pid=$!
  fake_port=""
  for _ in $(seq 100); do
    fake_port=$(sed -n 's/.* port \([0-9]*\) .*/\1/p' fake.out | head -1)
    [[ -n $fake_port ]] && break
    sleep 0.1
  done
  expect 1 "an ambiguous prefix is fatal" "$TESSERA" watch abcd --url "http://127.0.0.1:$fake_port"
  kill "$fake_pid" 2>/dev/null
  wait "$fake_pid" 2>/dev/null
  if grep -q "the job id prefix abcd is ambiguous: 2 jobs start with it" "$tmp/err" &&
    [[ $(grep -c "^  abcd[0-9a-f]\{28\} " "$tmp/err") == 2 ]]; then
    ok "the ambiguous prefix lists its candidates"
  else
    not_ok "an ambiguous prefix said: $(cat "$tmp/err")"
  fi
  expect 1 "a prefix no job has is fatal" "$TESSERA" cancel 0000000
  grep -q "no job id starts with 0000000" "$tmp/err" && ok "and says so" || not_ok "no-match said: $(cat "$tmp/err")"
  expect 0 "tessera fetch" "$TESSERA" fetch "$id" -d fetched
  png_signature "fetched/$id.png" && ok "fetch wrote a PNG" || not_ok "fetched PNG has no PNG signature"
  [[ -s fetched/$id.exr ]] && ok "fetch wrote the EXR" || not_ok "no EXR fetched"
  # A frame range: submit --watch shows its frames done; fetch downloads every frame numbered, one progress line.
  mkdir -p range && cp "$repo/examples/spinning_cube/SpinningCube.glb" range/ &&
    python3 -c 'import json, sys; d = json.load(open(sys.argv[1])); d["render"].update(width=16, height=9, spp=1, frames={"start": 1, "end": 3}); d["outputs"] = ["png"]; json.dump(d, open("range/job.json", "w"))' \
      "$repo/examples/spinning_cube/job.json"
  expect 0 "submit a frame range and watch it" "$TESSERA" submit range/job.json --watch
  grep -q "frames 3/3" "$tmp/out" && ok "watch shows the frames done" || not_ok "watch said: $(tail -2 "$tmp/out")"
  range_id=$(grep -o '[0-9a-f]\{32\}' "$tmp/out" | head -1)
  expect 0 "fetch a frame range" "$TESSERA" fetch "$range_id" -d frames
  [[ $(ls frames | grep -c "^$range_id\.000[123]\.png$") == 3 ]] && ok "fetch wrote the 3 frames numbered" \
    || not_ok "fetch wrote: $(ls frames)"
  grep -q "fetched 3/3 frames" "$tmp/err" && ok "fetch shows its progress" || not_ok "fetch said: $(cat "$tmp/err")"
  expect 1 "fetch refuses an unwritable output before downloading" "$TESSERA" fetch "$id" -o /nonexistent/x.png
  grep -qF "cannot write /nonexistent/x.png" "$tmp/err" && ok "fetch names the output" \
    || not_ok "fetch said: $(cat "$tmp/err")"
  expect 1 "fetch refuses a -d that cannot be made" "$TESSERA" fetch "$id" -d all.png/sub
  expect 0 "tessera submit --watch" "$TESSERA" submit small.json --spp 4 --watch
  expect 0 "tessera submit a long job" "$TESSERA" submit long.json
  long=$(cat "$tmp/out")
  expect 75 "fetch before the job finished is transient" "$TESSERA" fetch "$long" -d fetched
  # A running job is cancelled when the answer comes (its render then stops within a tile's time): cancel says so.
  for _ in $(seq 100); do
    "$TESSERA" list --state running | grep -q "$long" && break
    sleep 0.1
  done
  # One job renders at a time (--max-jobs 1): a second is queued, and cancelled before a pass it has no results.
  expect 0 "tessera submit a queued job" "$TESSERA" submit long.json
  queued=$(cat "$tmp/out")
  expect 0 "tessera cancel of a queued job" "$TESSERA" cancel "$queued"
  expect 1 "fetch of a job cancelled before a pass is fatal" "$TESSERA" fetch "$queued" -d unrendered
  grep -qF "job $queued cancelled: it has no results" "$tmp/err" && ok "fetch says it has no results" \
    || not_ok "fetch of a job cancelled before a pass said: $(cat "$tmp/err")"
  [[ ! -e unrendered ]] && ok "fetch made no directory for a job without results" || not_ok "unrendered/ made"
  wait_for_samples "$long"
  expect 0 "tessera cancel of a running job" "$TESSERA" cancel "$long"
  grep -qx "cancelled" "$tmp/out" && ok "cancel says the running job is cancelled" || not_ok "cancel printed: $(cat "$tmp/out")"
  expect 1 "watch a cancelled job exits 1" "$TESSERA" watch "$long"
  # A job cancelled after a pass keeps the image of its last complete pass, which fetch downloads as such.
  expect 0 "fetch of a job cancelled after a pass" "$TESSERA" fetch "$long" -d partial
  png_signature "partial/$long.png" && ok "fetch wrote the partial PNG" || not_ok "no partial PNG fetched"
  [[ -s partial/$long.exr ]] && ok "fetch wrote the partial EXR" || not_ok "no partial EXR fetched"
  grep -qE "job $long cancelled: its results are a partial image of [1-9][0-9]* of 65536 samples per pixel" \
    "$tmp/err" && ok "fetch says the image is partial, and of how many samples" || not_ok "fetch said: $(cat "$tmp/err")"
  expect 1 "cancel of an ended job is refused (409)" "$TESSERA" cancel "$id"
  grep -q "409" "$tmp/err" && ok "the refusal quotes the status" || not_ok "no status in the refusal"
  expect 1 "watch of an unknown job is fatal" "$TESSERA" watch 0123456789abcdef0123456789abcdef
  expect 1 "submit refuses the unknown material property" "$TESSERA" submit albdo.json
  if grep -qF 'unknown property "albdo" (did you mean "albedo"?) (at /scene/materials/m/albdo)' "$tmp/err"; then
    ok "the daemon and tessera render give the same message and pointer"
  else
    not_ok "the daemon said: $(cat "$tmp/err"); tessera render: $(cat render-albdo.err)"
  fi
  expect 1 "submit refuses a job with four errors" "$TESSERA" submit many.json
  if [[ $(grep -c "^tessera: submit: " "$tmp/err") == 5 ]] && grep -qF 'must be at least 1 (at /render/spp)' "$tmp/err" \
    && grep -qxF 'tessera: submit: more checks (material names, indices, assets, limits) follow once these errors are fixed' \
      "$tmp/err" \
    && grep -qF 'must be an integer (at /render/width)' "$tmp/err" \
    && grep -qF '(did you mean "lambert"?) (at /scene/materials/n/type)' "$tmp/err"; then
    ok "submit shows the daemon's four errors and that more checks follow, as render does"
  else
    not_ok "submit said: $(cat "$tmp/err"); render: $(cat render-many.err)"
  fi
  # One answer with the schema's errors and the renderer's that do not depend on them.
  expect 1 "submit refuses a misspelt property and an unknown material" "$TESSERA" submit mixed.json
  if grep -qF 'unknown property "albdo" (did you mean "albedo"?) (at /scene/materials/m/albdo)' "$tmp/err" \
    && grep -qF 'unknown material "purple"' "$tmp/err" && grep -qF "(at /scene/objects/0/material)" "$tmp/err"; then
    ok "submit names the unknown material with the schema's error, in one answer"
  else
    not_ok "submit of mixed.json said: $(cat "$tmp/err")"
  fi
  expect 1 "submit.sh of a job with four errors fails" "$curl_dir/submit.sh" many.json
  if [[ $(grep -c "^error: " "$tmp/err") == 5 ]] && grep -qF "error: must be an integer at /render/width" "$tmp/err" \
    && grep -qF "error: more checks" "$tmp/err"; then
    ok "submit.sh prints every error"
  else
    not_ok "submit.sh of many.json said: $(cat "$tmp/err")"
  fi
  echo '{"kind": "scene", "render": {"width": 0}}' >invalid.json
  expect 1 "a refused job is fatal" "$TESSERA" submit invalid.json
  grep -q "422" "$tmp/err" && ok "the refusal shows the problem" || not_ok "no problem shown"

  # The curl scripts, on the same daemon.
  expect 0 "submit.sh" "$curl_dir/submit.sh" small.json
  cid=$(cat "$tmp/out")
  expect 0 "watch.sh" "$curl_dir/watch.sh" "$cid"
  grep -q succeeded "$tmp/out" && ok "watch.sh printed the final state" || not_ok "watch.sh printed no final state"
  expect 0 "list.sh" "$curl_dir/list.sh"
  grep -q "$cid" "$tmp/out" && ok "list.sh shows the job" || not_ok "list.sh misses the job"
  expect 0 "fetch.sh" "$curl_dir/fetch.sh" "$cid" curl-out/
  png_signature curl-out/result.png && ok "fetch.sh wrote a PNG" || not_ok "fetch.sh PNG has no signature"
  grep -qx "curl-out/result.png" "$tmp/out" && ok "fetch.sh names DIR/result.png once with a slash" \
    || not_ok "fetch.sh printed: $(cat "$tmp/out")"
  expect 0 "submit.sh a long job" "$curl_dir/submit.sh" long.json
  clong=$(cat "$tmp/out")
  expect 0 "submit.sh a queued job" "$curl_dir/submit.sh" long.json
  cqueued=$(cat "$tmp/out")
  expect 1 "fetch.sh of an unfinished job fails" "$curl_dir/fetch.sh" "$cqueued" curl-long
  grep -q "results exist once it has succeeded" "$tmp/err" && ok "fetch.sh says the job has not finished" \
    || not_ok "fetch.sh of an unfinished job said: $(cat "$tmp/err")"
  expect 0 "cancel.sh" "$curl_dir/cancel.sh" "$cqueued"
  expect 1 "fetch.sh of a job cancelled before a pass fails" "$curl_dir/fetch.sh" "$cqueued" curl-cancelled/
  if grep -q "job $cqueued cancelled: it has no results" "$tmp/err" && ! grep -q "unbound" "$tmp/err"; then
    ok "fetch.sh says the cancelled job has no results, and nothing else"
  else
    not_ok "fetch.sh of a cancelled job said: $(cat "$tmp/err")"
  fi
  [[ ! -e curl-cancelled ]] && ok "fetch.sh made no directory for a job without results" || not_ok "curl-cancelled/ made"
  wait_for_samples "$clong"
  expect 0 "cancel.sh of a running job" "$curl_dir/cancel.sh" "$clong"
  "$TESSERA" watch "$clong" >/dev/null 2>&1  # until it has stopped its pass
  expect 0 "fetch.sh of a job cancelled after a pass" "$curl_dir/fetch.sh" "$clong" curl-partial
  png_signature curl-partial/result.png && ok "fetch.sh wrote the partial PNG" || not_ok "fetch.sh wrote no partial PNG"
  grep -qE "job $clong cancelled: its results are a partial image of [1-9][0-9]* of 65536 samples per pixel" \
    "$tmp/err" && ok "fetch.sh says the image is partial, and of how many samples" \
    || not_ok "fetch.sh of a partial job said: $(cat "$tmp/err")"
  expect 1 "cancel.sh of an ended job fails" "$curl_dir/cancel.sh" "$cid"
  grep -q "error: HTTP 409" "$tmp/err" && ok "cancel.sh says why" || not_ok "cancel.sh gave no reason"
  expect 1 "submit.sh of an invalid job fails" "$curl_dir/submit.sh" invalid.json
  expect 1 "watch.sh of an unknown job fails" "$curl_dir/watch.sh" 0123456789abcdef0123456789abcdef
  TESSERA_URL=http://127.0.0.1:9 expect 1 "list.sh without a daemon fails" "$curl_dir/list.sh"
  grep -q "is tesserad running" "$tmp/err" && ok "list.sh says how to start the daemon" || not_ok "list.sh said: $(cat "$tmp/err")"
fi

echo "$passed passed, $failed failed"
[[ $failed == 0 ]]
