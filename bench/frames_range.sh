# Sourced by the frame range benchmarks (bench/frames_daemon.sh, bench/frames_cluster.sh): run_range URL submits the
# spinning cube's animation (examples/spinning_cube) as one render.frames job to the tesserad at URL, at $width x
# $height, $spp spp, frames $start_frame to $end_frame in units of $chunk frames, waits for its end and prints its id
# and the seconds from its submission to its end. The caller sets `bench` (its name, for messages).
field() { python3 -c 'import json,sys; d=json.load(sys.stdin); print(eval("d"+sys.argv[1]))' "$1"; }
run_range() {
  local url=$1 asset job id state t0
  asset=$(curl -sS -X POST --data-binary @examples/spinning_cube/SpinningCube.glb -H 'Content-Type: model/gltf-binary' \
    "$url/v1/assets?name=SpinningCube.glb" | field '["id"]')
  job=$(python3 - "$asset" "$width" "$height" "$spp" "$start_frame" "$end_frame" "$chunk" <<'PY'
import json, sys
asset, w, h, spp, start, end, chunk = sys.argv[1:]
doc = json.load(open("examples/spinning_cube/job.json"))
doc["scene"]["gltf"] = asset
doc["render"].update(width=int(w), height=int(h), spp=int(spp), frames={"start": int(start), "end": int(end), "chunk": int(chunk)})
print(json.dumps(doc))
PY
)
  t0=$(date +%s.%N)
  id=$(curl -sS -X POST "$url/v1/jobs" -H 'Content-Type: application/json' -d "$job" | field '["id"]')
  while :; do
    state=$(curl -sS "$url/v1/jobs/$id" | field '["state"]')
    [[ $state == succeeded ]] && break
    [[ $state == failed || $state == cancelled ]] && { echo "$bench: the job $state" >&2; exit 1; }
    sleep 0.2
  done
  echo "$id $(echo "$(date +%s.%N) - $t0" | bc -l)"
}
