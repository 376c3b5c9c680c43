#!/usr/bin/env bash
# What an upload takes of tesserad's memory: for each kind of upload of about SIZE_MB megabytes (a .glb of a mesh; a
# .gltf with its .bin, multipart; a .gltf whose buffer is a base64 data: URI; a .glb that is one PNG texture; an .exr
# environment map; a multipart job with the first .glb), a daemon of its own on loopback, its resident memory (VmRSS) before the upload and its peak (VmHWM) after the
# answer, and the peak's rise as a multiple of the upload's size. The multipart job waits in the queue behind a long
# render, so that only its upload is measured.
#   bench/upload_memory.sh     (BUILD=build SIZE_MB=59)
# Figures, not a test (tests/integration/hostile_test.cpp, HostileTest.AnUploadPeaksUnderFourTimesItsSize, holds the
# bound); heaptrack around tesserad shows where a peak comes from.
set -euo pipefail
cd "$(dirname "$0")/.."
build=${BUILD:-build}; size_mb=${SIZE_MB:-59}
tesserad=$build/server/tesserad
[[ -x $tesserad ]] || { echo "upload_memory: no $tesserad (build the tesserad target)" >&2; exit 2; }
for tool in curl python3 oiiotool; do
  command -v $tool >/dev/null || { echo "upload_memory: needs $tool" >&2; exit 2; }
done

work=$(mktemp -d)
pid=""
stop() {
  if [[ -n $pid ]]; then
    kill -TERM "$pid" 2>/dev/null || true
    for _ in $(seq 50); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
    kill -KILL "$pid" 2>/dev/null || true
    wait "$pid" 2>/dev/null || true
    pid=""
  fi
}
trap 'stop; rm -rf "$work"' EXIT

python3 bench/big_assets.py "$work" "$size_mb"
# An equirectangular float map of about the same size, stored uncompressed.
width=$(python3 -c "import math; print(int(math.sqrt($size_mb * 1e6 / 24)) * 2)")
oiiotool --pattern checker "${width}x$((width / 2))" 3 -d float --compression none -o "$work/big.exr"
python3 -c "import json; d = json.load(open('proto/examples/cornell.json')); d['render'].update(width=128, height=128, spp=65536); print(json.dumps(d))" >"$work/long.json"

kb() { awk -v k="$1:" '$1 == k { print $2 }' "/proc/$pid/status"; }

# measure KIND FILES...: one daemon, one upload of FILES, one line of figures.
measure() {
  local kind=$1; shift
  rm -rf "$work/data" "$work/log"
  "$tesserad" --listen 127.0.0.1 --port 0 --data-dir "$work/data" --max-body-bytes 1073741824 --min-free-disk 0 \
    --threads 1 >"$work/log" 2>&1 &
  pid=$!
  for _ in $(seq 100); do grep -q "listening on" "$work/log" 2>/dev/null && break; sleep 0.1; done
  local url status bytes=0 f
  url=http://127.0.0.1:$(sed -n 's/^listening on http:\/\/127\.0\.0\.1:\([0-9]*\).*/\1/p' "$work/log" | head -1)
  for f in "$@"; do bytes=$((bytes + $(stat -c %s "$f"))); done
  if [[ $kind == "multipart job" ]]; then
    curl -sS -o /dev/null -H 'Content-Type: application/json' --data-binary @"$work/long.json" "$url/v1/jobs"
    sleep 1
  fi
  local before; before=$(kb VmRSS)
  case $kind in
    .glb | "textured .glb") status=$(curl -sS -o "$work/out" -w '%{http_code}' -H 'Content-Type: model/gltf-binary' \
                     --data-binary @"$1" "$url/v1/assets?name=big.glb") ;;
    ".gltf, data: URI") status=$(curl -sS -o "$work/out" -w '%{http_code}' -H 'Content-Type: model/gltf+json' \
                     --data-binary @"$1" "$url/v1/assets?name=big.gltf") ;;
    .exr) status=$(curl -sS -o "$work/out" -w '%{http_code}' -H 'Content-Type: image/x-exr' \
                     --data-binary @"$1" "$url/v1/assets?name=big.exr") ;;
    ".gltf + .bin") status=$(curl -sS -o "$work/out" -w '%{http_code}' -F "file=@$1;filename=big.gltf" \
                     -F "file=@$2;filename=big.bin" "$url/v1/assets") ;;
    "multipart job") status=$(curl -sS -o "$work/out" -w '%{http_code}' \
                     -F 'job={"kind":"scene","scene":{"gltf":"big.glb"},"render":{"width":16,"height":16,"spp":1}};type=application/json' \
                     -F "file=@$1;filename=big.glb" "$url/v1/jobs") ;;
  esac
  local peak; peak=$(kb VmHWM)
  stop
  awk -v k="$kind" -v s="$status" -v n="$bytes" -v b="$before" -v p="$peak" 'BEGIN {
    printf "%-18s %s  %6.1f MB  resident before %6.1f MB  peak %6.1f MB  rise %6.1f MB = %.2fx the upload\n",
           k, s, n / 1e6, b * 1024 / 1e6, p * 1024 / 1e6, (p - b) * 1024 / 1e6, (p - b) * 1024 / n }'
}

measure .glb "$work/big.glb"
measure ".gltf + .bin" "$work/big.gltf" "$work/big.bin"
measure ".gltf, data: URI" "$work/embedded.gltf"
measure "textured .glb" "$work/textured.glb"
measure .exr "$work/big.exr"
measure "multipart job" "$work/big.glb"
