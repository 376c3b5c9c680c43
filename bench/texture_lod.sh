#!/usr/bin/env bash
# How sharp minified textures come out: a text-like panel (a 1024x1024 texture of random 5x7 glyphs, strokes two
# texels wide) rendered at SIZE pixels with the ray-cone level of detail, against the same view rendered at
# REF_SCALE x SIZE and box-filtered down to SIZE (the supersampled reference, each output pixel the mean of its
# REF_SCALE^2 subpixels: at 8x the reference's own texture footprints are an eighth of an output pixel or less, so it
# is close to the exact box-filtered image whatever level-of-detail rule made it). Prints
# the RMSE of each against the reference (linear radiance, every pixel and channel, by OpenImageIO's idiff), for the
# panel facing the camera (about 4 texels a pixel) and as a floor seen at a grazing angle (about 13 degrees).
#
#   bench/texture_lod.sh
#   env: BUILD=build SIZE=256 SPP=16 REF_SCALE=8 REF_SPP=16 THREADS=<all>
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD=${BUILD:-build}
SIZE=${SIZE:-256}
SPP=${SPP:-16}
REF_SPP=${REF_SPP:-16}
REF_SCALE=${REF_SCALE:-8}
TESSERA=$BUILD/clients/cli/tessera
threads=()
[[ -n ${THREADS:-} ]] && threads=(--threads "$THREADS")
[[ -x $TESSERA ]] || { echo "build $TESSERA first (cmake --build $BUILD --target tessera)" >&2; exit 1; }
for tool in idiff oiiotool python3; do
  command -v $tool >/dev/null || { echo "$tool not found (apt-get install openimageio-tools python3)" >&2; exit 1; }
done
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

# The panel: dark glyphs on white, as a binary PPM, then PNG.
python3 - "$tmp/panel.ppm" <<'EOF'
import random, sys
random.seed(25)
n, cell_w, cell_h, scale = 1024, 12, 16, 2  # glyph cells of 6x8 strokes, each stroke 2x2 texels
img = bytearray([255]) * (n * n * 3)
for cy in range(0, n - cell_h, cell_h):
    for cx in range(0, n - cell_w, cell_w):
        glyph = [[random.random() < 0.45 for _ in range(5)] for _ in range(7)]
        for gy in range(7):
            for gx in range(5):
                if not glyph[gy][gx]:
                    continue
                for dy in range(scale):
                    for dx in range(scale):
                        i = ((cy + gy * scale + dy) * n + cx + gx * scale + dx) * 3
                        img[i:i + 3] = b"\x10\x10\x10"
with open(sys.argv[1], "wb") as f:
    f.write(b"P6\n%d %d\n255\n" % (n, n) + bytes(img))
EOF
oiiotool "$tmp/panel.ppm" -d uint8 -o "$tmp/panel.png"

# scene NAME CORNER EDGE2 FROM: the panel (2 x 2, emission = the texture, nothing else lit) seen by a 40-degree camera
# looking at the origin.
scene() {
  cat >"$tmp/$1.json" <<EOF
{"kind": "scene",
 "scene": {"materials": {"panel": {"type": "lambert", "albedo": 0, "emission": {"texture": "panel.png"}}},
           "objects": [{"shape": "rectangle", "corner": $2, "edge1": [2, 0, 0], "edge2": $3, "material": "panel"}],
           "camera": {"from": $4, "to": [0, 0, 0], "fov_deg": 40}},
 "render": {"width": $SIZE, "height": $SIZE, "spp": $SPP, "max_depth": 1}}
EOF
}
scene facing '[-1, -1, 0]' '[0, 2, 0]' '[0, 0, 2.75]'
scene grazing '[-1, 0, 1]' '[0, 0, -2]' '[0, 0.5, 2.2]'
rmse() { { idiff -v -a "$1" "$2" 2>/dev/null || true; } | sed -n 's/^ *RMS error = \([0-9.e+-]*\).*/\1/p'; }

printf '%-8s %6s %6s %12s\n' view size spp rmse_vs_ref
for view in facing grazing; do
  big=$((REF_SCALE * SIZE))
  "$TESSERA" render "$tmp/$view.json" --width "$big" --height "$big" --spp "$REF_SPP" --seed 99 "${threads[@]}" -q 2>"$tmp/log" \
    -o "$tmp/$view-big.exr"
  oiiotool "$tmp/$view-big.exr" --resize:filter=box "${SIZE}x${SIZE}" -o "$tmp/$view-ref.exr"
  "$TESSERA" render "$tmp/$view.json" --spp "$SPP" --seed 7 "${threads[@]}" -q -o "$tmp/$view.exr" 2>"$tmp/log"
  printf '%-8s %6s %6s %12s\n' "$view" "$SIZE" "$SPP" "$(rmse "$tmp/$view-ref.exr" "$tmp/$view.exr")"
done
