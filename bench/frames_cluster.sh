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
bench=frames_cluster
daemon_args=(--max-jobs 1 --log-level warn)
source bench/postgres_cluster.sh
source bench/frames_range.sh
width=${WIDTH:-640}; height=${HEIGHT:-360}; spp=${SPP:-16}; frames=${FRAMES:-1-48}; chunk=${CHUNK:-1}
rounds=${ROUNDS:-3}
start_frame=${frames%-*}; end_frame=${frames#*-}
threads=${THREADS:-$(nproc)}
node_threads=${NODE_THREADS:-$(((threads + 1) / 2))}
median() { sort -g | awk '{a[NR] = $1} END {print (NR % 2) ? a[(NR + 1) / 2] : (a[NR / 2] + a[NR / 2 + 1]) / 2}'; }

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

# One round of a configuration: run_config NAME LABEL NODES THREADS (each node), on a fresh database and data directory.
# Appends the seconds to the array named NAME and the median render time a frame to NAME_render; prints its line.
run_config() {
  local name=$1 label=$2 nodes=$3 node_threads=$4 before id s rs fl ol ws
  new_database
  before=$(loadavg)
  for i in $(seq "$nodes"); do
    start "$name-$r-$i" "$work/$name-$r" --store "$uri" --node "n$i" --threads "$node_threads"
  done
  read -r id s <<<"$(run_range "$url")"
  [[ -n $s ]] || exit 1
  curl -sS "$url/v1/jobs/$id/log" >"$work/$name-$r.joblog"
  [[ $(curl -sS "$url/v1/jobs/$id" | field '["frames"]["done"]') == $(grep -c ': done in ' "$work/$name-$r.joblog") ]] ||
    { echo "frames_cluster: a frame was rendered more than once or not at all" >&2; exit 1; }
  stop_all
  read -r rs fl ol ws <<<"$(overhead "$work/$name-$r.joblog")"
  eval "$name+=($s); ${name}_render+=($rs)"
  printf 'round %s, %s: %.1f s, %.0f frames/hour; load average %s -> %s; a frame: render %s s, load+BVH %s s (first of a unit) / %s s (others), worker start %s s\n' \
    "$r" "$label" "$s" "$(echo "3600 * $n / $s" | bc -l)" "$before" "$(loadavg)" "$rs" "$fl" "$ol" "$ws"
}

loadavg() { cut -d' ' -f1-3 /proc/loadavg; }
n=$(((end_frame - start_frame) + 1))
printf '%s, %s hardware threads; %d frames (%s) of the spinning cube at %sx%s, %s spp, %s frame(s) a unit\n' \
  "$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ *//')" "$(nproc)" "$n" "$frames" "$width" "$height" \
  "$spp" "$chunk"
one=(); two=(); one_render=(); two_render=()
for r in $(seq "$rounds"); do
  run_config one "one node ($threads threads)" 1 "$threads"
  run_config two "two nodes ($node_threads threads each)" 2 "$node_threads"
done
t1=$(printf '%s\n' "${one[@]}" | median); t2=$(printf '%s\n' "${two[@]}" | median)
summary() {
  printf '%s median %.1f s, %.2f s a frame, %.0f frames/hour   (rounds: %s)\n' "$1" "$2" "$(echo "$2 / $n" | bc -l)" \
    "$(echo "3600 * $n / $2" | bc -l)" "$3"
}
summary "one node: " "$t1" "${one[*]}"
summary "two nodes:" "$t2" "${two[*]}"
printf 'two nodes / one node, frames per hour: %.3f\n' "$(echo "$t1 / $t2" | bc -l)"
# What a frame costs besides its render (one node: the wall time a frame less the median render time a frame).
r1=$(printf '%s\n' "${one_render[@]}" | median)
printf 'one node, a frame besides its render: %.2f s of %.2f s (%.0f %%)\n' "$(echo "$t1 / $n - $r1" | bc -l)" \
  "$(echo "$t1 / $n" | bc -l)" "$(echo "100 * ($t1 / $n - $r1) / ($t1 / $n)" | bc -l)"
