#!/usr/bin/env bash
# What splitting one frame into work units across nodes buys and costs, on this machine, against a throw-away
# PostgreSQL (initdb in a temporary directory, a Unix socket; as `nobody` when run as root):
#   1. the same frame on one node with two render threads (SQLite, rendered whole: today's single-node path) against
#      two nodes with one thread each (one PostgreSQL store, one shared data directory, the frame split into UNITS
#      units): each render's wall time from submission to its result, and the two nodes' throughput as a share of
#      the one node's (goal: at least 0.9);
#   2. the time from a unit's end to its merge: from the last unit's end to the job's result (claiming the merge,
#      reading the units' films, merging them, writing the EXR), in the store's times;
#   3. the claims per second the store sustains (tessera-claim-load: 200 jobs of 20 units, each unit and merge claimed
#      and ended by 4 connections);
#   4. the overhead per unit: one node with one thread renders the frame in UNITS units (on PostgreSQL); its wall
#      time less its units' render time, per unit (and, for reference, the frame rendered whole).
#   bench/cluster_scaling.sh     (BUILD=build SIZE=128 SPP=1024 UNITS=8 ROUNDS=1)
# Figures, not a test: run it on an otherwise idle machine.
set -euo pipefail
cd "$(dirname "$0")/.."
build=${BUILD:-build}; size=${SIZE:-128}; spp=${SPP:-1024}; units=${UNITS:-8}; rounds=${ROUNDS:-1}
tesserad=$build/server/tesserad
claim_load=$build/bench/tessera-claim-load
for f in "$tesserad" "$claim_load"; do
  [[ -x $f ]] || { echo "cluster_scaling: no $f (cmake -DTESSERA_BUILD_BENCH=ON, then build)" >&2; exit 2; }
done
command -v curl >/dev/null || { echo "cluster_scaling: needs curl" >&2; exit 2; }
bench=cluster_scaling
daemon_args=(--log-level info)
source bench/postgres_cluster.sh

python3 - "$size" "$spp" >"$work/job.json" <<'PY'
import json, sys
j = json.load(open("proto/examples/cornell.json"))
s, spp = int(sys.argv[1]), int(sys.argv[2])
j["render"].update({"width": s, "height": s, "spp": spp, "exr_precision": "float"})
j["outputs"] = ["exr"]
print(json.dumps(j))
PY
unit_pixel_samples=$(( (size * size * spp + units - 1) / units ))

# Submits the job to $url and waits for its end; prints the wall seconds from submission to the result, and keeps
# its EXR in $work/$1.exr.
render() {
  local t0 id state
  t0=$(date +%s.%N)
  id=$(curl -sS -H 'Content-Type: application/json' --data-binary @"$work/job.json" "$url/v1/jobs" |
    sed -n 's/.*"id":"\([^"]*\)".*/\1/p')
  [[ -n $id ]] || { echo "cluster_scaling: the job was refused" >&2; exit 1; }
  for _ in $(seq 36000); do
    state=$(curl -sS "$url/v1/jobs/$id" | sed -n 's/.*"state":"\([^"]*\)".*/\1/p')
    [[ $state == succeeded ]] && break
    [[ $state == failed || $state == cancelled ]] && { echo "cluster_scaling: the job $state" >&2; exit 1; }
    sleep 0.05
  done
  echo "$(date +%s.%N) - $t0" | bc -l | xargs printf '%.2f\n'
  curl -sS -o "$work/$1.exr" "$url/v1/jobs/$id/result.exr"
}
median() { sort -g | awk '{a[NR] = $1} END {print (NR % 2) ? a[(NR + 1) / 2] : (a[NR / 2] + a[NR / 2 + 1]) / 2}'; }

echo "frame: Cornell box ${size}x${size}, $spp spp, path tracer; $units units of $((spp / units)) spp on the cluster"
one=(); two=()
for r in $(seq "$rounds"); do
  start one-$r "$work/one-$r" --threads 2
  one+=("$(render one)")
  stop_all
  new_database
  start a-$r "$work/shared-$r" --store "$uri" --node a --threads 1 --unit-pixel-samples "$unit_pixel_samples"
  start b-$r "$work/shared-$r" --store "$uri" --node b --threads 1 --unit-pixel-samples "$unit_pixel_samples"
  two+=("$(render two)")
  cmp -s "$work/one.exr" "$work/two.exr" || { echo "cluster_scaling: the two-node EXR differs" >&2; exit 1; }
  # From the last unit's end to the job's result; per node, the units it rendered.
  merge_ms=$(psql_in "SELECT j.finished_at - MAX(u.finished_at) FROM tessera_jobs j JOIN tessera_units u ON \
    u.job_id = j.id AND u.idx < j.units GROUP BY j.id, j.finished_at")
  per_node=$(psql_in "SELECT u.node || ':' || COUNT(*) FROM tessera_units u JOIN tessera_jobs j ON j.id = u.job_id \
    WHERE u.idx < j.units GROUP BY u.node ORDER BY u.node" | tr '\n' ' ')
  stop_all
done
t1=$(printf '%s\n' "${one[@]}" | median); t2=$(printf '%s\n' "${two[@]}" | median)
echo "one node, 2 threads, whole (SQLite):      ${t1} s   (rounds: ${one[*]})"
echo "two nodes, 1 thread each, $units units (PostgreSQL): ${t2} s   (rounds: ${two[*]}; units per node: ${per_node})"
echo "throughput of two nodes / one node:       $(echo "$t1 / $t2" | bc -l | xargs printf '%.3f')   (goal >= 0.9)"
echo "EXR of the two nodes = EXR of the one node: yes (cmp)"
echo "last unit's end -> merged result:         ${merge_ms} ms"

# Claims per second.
new_database
"$claim_load" "$uri" 200 20 4 | sed 's/^/store: /'

# Overhead per unit: one node, one thread, the frame in units: its wall time less its units' render time (each
# session's own clock, passes and checkpoints included), per unit. What is left is each unit's claim, scene load and
# end, and the merge. (The frame rendered whole is timed too, for reference: on a busy machine the difference of two
# runs is noisier than this.)
new_database
start whole "$work/whole" --store "$uri" --node w --threads 1 --unit-pixel-samples 0
tw=$(render whole)
stop_all
new_database
start split "$work/split" --store "$uri" --node s --threads 1 --unit-pixel-samples "$unit_pixel_samples"
ts=$(render split)
stop_all
rendering=$(psql_in "SELECT ROUND(SUM(u.elapsed_s)::numeric, 2) FROM tessera_units u JOIN tessera_jobs j ON j.id = u.job_id \
  WHERE u.idx < j.units")
echo "one node, 1 thread: whole ${tw} s; in $units units ${ts} s, of which ${rendering} s rendering: overhead per unit" \
  "$(echo "($ts - $rendering) * 1000 / $units" | bc -l | xargs printf '%.0f') ms"
