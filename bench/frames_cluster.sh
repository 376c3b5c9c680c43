#!/usr/bin/env bash
# Frame ranges on one node and on two: frames per hour of the 48-frame spinning cube (examples/spinning_cube) at
# 640×360, submitted as one render.frames job to one tesserad, then to two tesserads sharing one PostgreSQL (a
# throw-away cluster: initdb in a temporary directory, a Unix socket; as `nobody` when run as root) and one data
# directory, as a cluster's nodes do; each configuration ROUNDS times, with the medians and the load average of every
# run. Both nodes run on this machine, so they share its cores: one node gets every render thread, each of two nodes
# half of them (NODE_THREADS), so that two nodes against one measures what spreading a range over nodes costs, not
# more hardware. From each job's log it gives the per-frame overhead: a frame's render time against its scene load
# and BVH (the first frame of a unit, in a fresh worker process, and the others of a chunk), the worker's start a
# unit, and the rest of the wall time a frame (claims, outputs, the status).
#   bench/frames_cluster.sh      (env: BUILD=build WIDTH=640 HEIGHT=360 SPP=16 FRAMES=1-48 CHUNK=1 ROUNDS=3
#                                 THREADS=<all> NODE_THREADS=<THREADS/2>)
# Figures, not a test: run it on an otherwise idle machine.
set -euo pipefail
cd "$(dirname "$0")/.."
build=${BUILD:-build}
tesserad=$build/server/tesserad
[[ -x $tesserad ]] || { echo "frames_cluster: build $tesserad first" >&2; exit 2; }
command -v curl >/dev/null || { echo "frames_cluster: needs curl" >&2; exit 2; }
bindir=${TESSERA_PG_BINDIR:-$(ls -d /usr/lib/postgresql/*/bin 2>/dev/null | sort -V | tail -1)}
[[ -x $bindir/initdb ]] || { echo "frames_cluster: no PostgreSQL server programs (apt install postgresql)" >&2; exit 2; }
width=${WIDTH:-640}; height=${HEIGHT:-360}; spp=${SPP:-16}; frames=${FRAMES:-1-48}; chunk=${CHUNK:-1}
rounds=${ROUNDS:-3}
start_frame=${frames%-*}; end_frame=${frames#*-}
threads=${THREADS:-$(nproc)}
node_threads=${NODE_THREADS:-$(((threads + 1) / 2))}

work=$(mktemp -d)
chmod 755 "$work"
as_pg=()
[[ $(id -u) == 0 ]] && as_pg=(runuser -u nobody --)
pids=()
stop_all() {
  for p in "${pids[@]}"; do kill -TERM "$p" 2>/dev/null || true; done
  for p in "${pids[@]}"; do wait "$p" 2>/dev/null || true; done
  pids=()
}
cleanup() {
  stop_all
  [[ -d $work/pg ]] && "${as_pg[@]}" "$bindir/pg_ctl" -D "$work/pg/data" -m immediate -w stop >/dev/null 2>&1 || true
  rm -rf "$work"
}
trap cleanup EXIT
trap 'exit 130' INT TERM

mkdir "$work/pg" && chmod 777 "$work/pg"
"${as_pg[@]}" "$bindir/initdb" -D "$work/pg/data" -U tessera --auth=trust -E UTF8 --locale=C --no-sync >/dev/null
"${as_pg[@]}" "$bindir/pg_ctl" -D "$work/pg/data" -w -l "$work/pg/server.log" \
  -o "-k $work/pg -c listen_addresses= -c fsync=off" start >/dev/null
db=0
# A fresh database; its URI in $uri.
new_database() {
  db=$((db + 1))
  "${as_pg[@]}" "$bindir/psql" -h "$work/pg" -U tessera -d postgres -qAtc "CREATE DATABASE bench$db" >/dev/null
  uri="postgresql://tessera@/bench$db?host=$work/pg"
}

# Starts a daemon: start NAME DATA_DIR ARGS...; sets $url (of the last one started).
start() {
  local name=$1 dir=$2; shift 2
  mkdir -p "$dir"
  : >"$work/$name.out"
  "$tesserad" --listen 127.0.0.1 --port 0 --data-dir "$dir" --grace-s 2 --max-jobs 1 --log-level warn "$@" \
    >"$work/$name.out" 2>"$work/$name.log" &
  pids+=($!)
  url=""
  for _ in $(seq 100); do
    url=$(sed -n 's/.*listening on \(http:[^ ]*\).*/\1/p' "$work/$name.out")
    [[ -n $url ]] && break
    sleep 0.1
  done
  [[ -n $url ]] || { cat "$work/$name.log" >&2; echo "frames_cluster: tesserad did not start" >&2; exit 1; }
  url=${url%/}
}
field() { python3 -c 'import json,sys; d=json.load(sys.stdin); print(eval("d"+sys.argv[1]))' "$1"; }
median() { sort -g | awk '{a[NR] = $1} END {print (NR % 2) ? a[(NR + 1) / 2] : (a[NR / 2] + a[NR / 2 + 1]) / 2}'; }

# Submits the range to $url and waits for its last frame; prints the seconds from submission to the job's end and
# saves its log as $work/$1.joblog.
render_range() {
  local asset job id state t0
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
    [[ $state == failed || $state == cancelled ]] && { echo "frames_cluster: the job $state" >&2; exit 1; }
    sleep 0.2
  done
  echo "$(date +%s.%N) - $t0" | bc -l | xargs printf '%.2f\n'
  curl -sS "$url/v1/jobs/$id/log" >"$work/$1.joblog"
  [[ $(curl -sS "$url/v1/jobs/$id" | field '["frames"]["done"]') == $(grep -c ': done in ' "$work/$1.joblog") ]] ||
    { echo "frames_cluster: a frame was rendered more than once or not at all" >&2; exit 1; }
}

# The per-frame figures of a job's log (medians, in seconds): render, scene load and BVH of a unit's first frame
# and of its other frames, and a worker's start (from "loading the scene" to the unit's first line in the worker).
overhead() {
  python3 - "$1" <<'PY'
import datetime, re, statistics, sys
render, first, rest, start = [], [], [], []
loading = {}  # node -> when it began loading a unit
first_of_unit = {}  # node -> whether its next frame done is its unit's first
for line in open(sys.argv[1]):
    # "<time>  <node>  <text>" (a store shared by nodes) or "<time>  <text>"
    m = re.match(r"(\S+)  (?:(\S+)  )?(.*)$", line.rstrip("\n"))
    if not m:
        continue
    try:
        t = datetime.datetime.fromisoformat(m.group(1).replace("Z", "+00:00")).timestamp()
    except ValueError:
        continue
    node, text = m.group(2) or "", m.group(3)
    if text == "loading the scene":
        loading[node] = t
    elif re.match(r"unit \d+ of \d+: rendering", text) and node in loading:
        start.append(t - loading.pop(node))
        first_of_unit[node] = True
    m = re.match(r"frame (-?\d+): done in ([0-9.]+) s \(scene load and BVH ([0-9.]+) s\)", text)
    if m:
        render.append(float(m.group(2)))
        (first if first_of_unit.get(node, True) else rest).append(float(m.group(3)))
        first_of_unit[node] = False
med = lambda xs: statistics.median(xs) if xs else float("nan")
print(f"{med(render):.3f} {med(first):.3f} {med(rest):.4f} {med(start):.3f}")
PY
}

loadavg() { cut -d' ' -f1-3 /proc/loadavg; }
printf '%s, %s hardware threads; %d frames (%s) of the spinning cube at %sx%s, %s spp, %s frame(s) a unit\n' \
  "$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ *//')" "$(nproc)" \
  $(((end_frame - start_frame) + 1)) "$frames" "$width" "$height" "$spp" "$chunk"
n=$(((end_frame - start_frame) + 1))
one=(); two=(); one_render=(); two_render=(); lines=()
for r in $(seq "$rounds"); do
  new_database
  before=$(loadavg)
  start one-$r "$work/one-$r" --store "$uri" --node solo --threads "$threads"
  s=$(render_range one-$r)
  stop_all
  one+=("$s")
  read -r rs fl ol ws <<<"$(overhead "$work/one-$r.joblog")"
  one_render+=("$rs")
  lines+=("round $r, one node ($threads threads): $s s, $(echo "3600 * $n / $s" | bc -l | xargs printf '%.0f') frames/hour; load average $before -> $(loadavg); a frame: render $rs s, load+BVH $fl s (first of a unit) / $ol s (others), worker start $ws s")
  new_database
  before=$(loadavg)
  start a-$r "$work/shared-$r" --store "$uri" --node a --threads "$node_threads"
  start b-$r "$work/shared-$r" --store "$uri" --node b --threads "$node_threads"
  s=$(render_range two-$r)
  stop_all
  two+=("$s")
  read -r rs fl ol ws <<<"$(overhead "$work/two-$r.joblog")"
  two_render+=("$rs")
  lines+=("round $r, two nodes ($node_threads threads each): $s s, $(echo "3600 * $n / $s" | bc -l | xargs printf '%.0f') frames/hour; load average $before -> $(loadavg); a frame: render $rs s, load+BVH $fl s (first of a unit) / $ol s (others), worker start $ws s")
  printf '%s\n' "${lines[@]: -2}"
done
t1=$(printf '%s\n' "${one[@]}" | median); t2=$(printf '%s\n' "${two[@]}" | median)
printf 'one node:  median %.1f s, %.2f s a frame, %.0f frames/hour   (rounds: %s)\n' "$t1" "$(echo "$t1 / $n" | bc -l)" \
  "$(echo "3600 * $n / $t1" | bc -l)" "${one[*]}"
printf 'two nodes: median %.1f s, %.2f s a frame, %.0f frames/hour   (rounds: %s)\n' "$t2" "$(echo "$t2 / $n" | bc -l)" \
  "$(echo "3600 * $n / $t2" | bc -l)" "${two[*]}"
printf 'two nodes / one node, frames per hour: %.3f\n' "$(echo "$t1 / $t2" | bc -l)"
# What a frame costs besides its render (one node: the wall time a frame less the median render time a frame).
r1=$(printf '%s\n' "${one_render[@]}" | median)
printf 'one node, a frame besides its render: %.2f s of %.2f s (%.0f %%)\n' "$(echo "$t1 / $n - $r1" | bc -l)" \
  "$(echo "$t1 / $n" | bc -l)" "$(echo "100 * ($t1 / $n - $r1) / ($t1 / $n)" | bc -l)"
