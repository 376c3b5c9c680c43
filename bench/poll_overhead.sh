#!/usr/bin/env bash
# What status polling costs a render: tesserad on loopback renders the Cornell box ROUNDS times quiet (nobody polls)
# and ROUNDS times polled (tessera-poll-load at RATE requests/s on GET /v1/jobs/{id} of that job for the whole render),
# alternating quiet/polled then polled/quiet, and prints the median samples/s of each, the throughput cost, the
# requests served, tesserad's CPU time per status request (its threads other than the render threads, less what they
# spend in a quiet render) and the share of the machine's cores that RATE requests/s take.
#   bench/poll_overhead.sh     (BUILD=build RATE=1000 ROUNDS=3 SIZE=512 SPP=48 CONNECTIONS=2)
# Figures, not a test: run it on an otherwise idle machine.
set -euo pipefail
cd "$(dirname "$0")/.."
build=${BUILD:-build}; rate=${RATE:-1000}; rounds=${ROUNDS:-3}; size=${SIZE:-512}; spp=${SPP:-48}
connections=${CONNECTIONS:-2}
tesserad=$build/server/tesserad
load=$build/bench/tessera-poll-load
for f in "$tesserad" "$load"; do
  [[ -x $f ]] || { echo "poll_overhead: no $f (cmake -DTESSERA_BUILD_BENCH=ON, then build)" >&2; exit 2; }
done
command -v curl >/dev/null || { echo "poll_overhead: needs curl" >&2; exit 2; }

work=$(mktemp -d)
pid=""
load_pid=""
cleanup() {
  if [[ -n $load_pid ]]; then kill -TERM "$load_pid" 2>/dev/null || true; wait "$load_pid" 2>/dev/null || true; fi
  if [[ -n $pid ]]; then
    kill -TERM "$pid" 2>/dev/null || true
    for _ in $(seq 50); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
    kill -KILL "$pid" 2>/dev/null || true
    wait "$pid" 2>/dev/null || true
  fi
  rm -rf "$work"
}
trap cleanup EXIT
trap 'exit 130' INT TERM

"$tesserad" --listen 127.0.0.1 --port 0 --data-dir "$work/data" --grace-s 2 --log-level warn \
  >"$work/tesserad.out" 2>"$work/tesserad.log" &
pid=$!
url=""
for _ in $(seq 100); do
  url=$(sed -n 's/.*listening on \(http:[^ ]*\).*/\1/p' "$work/tesserad.out")
  [[ -n $url ]] && break
  kill -0 "$pid" 2>/dev/null || break
  sleep 0.1
done
[[ -n $url ]] || { cat "$work/tesserad.log" >&2; echo "poll_overhead: tesserad did not start" >&2; exit 1; }
url=${url%/}
render_threads=$(curl -sS "$url/metrics" | awk '$1 == "tessera_render_threads" {print $2}')
cores=$(nproc)
tck=$(getconf CLK_TCK)

python3 - "$size" "$spp" >"$work/job.json" <<'PY'
import json, sys
j = json.load(open("proto/examples/cornell.json"))
s, spp = int(sys.argv[1]), int(sys.argv[2])
j["render"].update({"width": s, "height": s, "spp": spp})
j["outputs"] = ["png"]
print(json.dumps(j))
PY

# CPU time of tesserad: the process's utime + stime (/proc/PID/stat, in clock ticks) and, to tell the render threads
# from the rest, every thread's time on a CPU in ns (/proc/PID/task/TID/schedstat). Per-thread utime/stime are no use
# for that: they are sampled at clock ticks, and the HTTP work is spread over hundreds of pool threads that each run
# far less than a tick at a time. A thread that ends between the listing and the read is left out.
process_ms() { awk -v tck="$tck" '{sub(/^.*\) /, ""); printf "%.0f\n", ($12 + $13) * 1000 / tck}' /proc/"$pid"/stat; }
thread_ns() {
  awk '{n = split(FILENAME, p, "/"); print p[n - 1], $1}' /proc/"$pid"/task/*/schedstat 2>/dev/null || true
}
# CPU ms of the threads listed in file $2 between snapshots $1 and $3 (every thread when $2 is "-").
cpu_ms() {
  awk -v only="$2" '
    FILENAME == ARGV[1] { before[$1] = $2; next }
    only != "-" && FILENAME == only { keep[$1] = 1; next }
    only == "-" || ($1 in keep) { sum += $2 - before[$1] }
    END { printf "%.0f\n", sum / 1e6 }' "$1" $([[ $2 == - ]] || echo "$2") "$3"
}
now_s() { date +%s.%N; }
status_field() { sed -n "s/.*\"$1\":\([^,}]*\).*/\1/p" | head -1 | tr -d '"'; }

submit() {
  curl -sS -X POST "$url/v1/jobs" -H 'Content-Type: application/json' --data-binary @"$work/job.json" |
    sed -n 's/^{"id":"\([^"]*\)".*/\1/p; s/.*[{,]"id":"\([^"]*\)".*/\1/p' | head -1
}

# Waits for the job to end on its event stream (no polling: the stream ends with the job's terminal state).
wait_for_end() {
  local state=""
  for _ in $(seq 20); do
    curl -sS -N --max-time 600 "$url/v1/jobs/$1/events" >/dev/null 2>&1 || true
    state=$(curl -sS "$url/v1/jobs/$1" | status_field state)
    case $state in succeeded | failed | cancelled) break ;; esac
    sleep 0.5
  done
  [[ $state == succeeded ]] || { echo "poll_overhead: job $1 ended $state" >&2; exit 1; }
}

printf 'tesserad %s: %sx%s Cornell box, %s spp, %s render threads on %s cores; %s rounds; polled at %s requests/s on %s connections\n' \
  "$url" "$size" "$size" "$spp" "$render_threads" "$cores" "$rounds" "$rate" "$connections"
render_tids=$work/render.tids
: >"$work/runs"
run() {  # run quiet|polled
  local mode=$1 id t0 t1 requests=0 client_cpu=0 status proc_before proc_ms
  proc_before=$(process_ms)
  thread_ns >"$work/before"
  t0=$(now_s)
  id=$(submit)
  [[ -n $id ]] || { echo "poll_overhead: submit failed" >&2; exit 1; }
  if [[ $mode == polled ]]; then
    "$load" --rate "$rate" --connections "$connections" --duration 900 "$url/v1/jobs/$id" >"$work/load.out" 2>&1 &
    load_pid=$!
  fi
  wait_for_end "$id"
  if [[ $mode == polled ]]; then
    kill -INT "$load_pid"
    wait "$load_pid" || { cat "$work/load.out" >&2; echo "poll_overhead: not every status request was a 200" >&2; exit 1; }
    load_pid=""
    requests=$(awk '$1 == "sent" {print $2}' "$work/load.out")
    client_cpu=$(awk '$1 == "client_cpu_ms" {print $2}' "$work/load.out")
  fi
  t1=$(now_s)
  thread_ns >"$work/after"
  proc_ms=$(( $(process_ms) - proc_before ))
  # The render threads: the pool's busiest threads in the first (quiet) render.
  if [[ ! -s $render_tids ]]; then
    awk 'FILENAME == ARGV[1] { before[$1] = $2; next } { printf "%s %.0f\n", $1, $2 - before[$1] }' "$work/before" \
      "$work/after" | sort -k2,2nr |
      head -n "$render_threads" | awk '{print $1}' >"$render_tids"
  fi
  status=$(curl -sS "$url/v1/jobs/$id")
  local sps elapsed spp_done total_ms render_ms
  sps=$(status_field samples_per_s <<<"$status")
  elapsed=$(status_field elapsed_s <<<"$status")
  spp_done=$(status_field samples_done <<<"$status")
  total_ms=$(cpu_ms "$work/before" - "$work/after")
  render_ms=$(cpu_ms "$work/before" "$render_tids" "$work/after")
  echo "$mode $sps $elapsed $spp_done $requests $proc_ms $total_ms $render_ms $(awk -v a="$t0" -v b="$t1" 'BEGIN {print b - a}') $client_cpu" >>"$work/runs"
  printf '  %-6s %8.4g samples/s  %5.2f s render  %6s requests  tesserad CPU %6s ms (/proc stat: %s ms), render threads %s ms\n' \
    "$mode" "$sps" "$elapsed" "$requests" "$total_ms" "$proc_ms" "$render_ms"
  if [[ $mode == polled ]]; then sed -n 's/^/           /; /^ *\(sent\|status\|latency_ms\)/p' "$work/load.out"; fi
  curl -sS -o /dev/null -X DELETE "$url/v1/jobs/$id"
}

for round in $(seq "$rounds"); do
  if (( round % 2 == 1 )); then run quiet; run polled; else run polled; run quiet; fi
done

python3 - "$work/runs" "$size" "$rate" "$cores" <<'PY'
import statistics, sys
runs = [l.split() for l in open(sys.argv[1])]
size, rate, cores = int(sys.argv[2]), float(sys.argv[3]), int(sys.argv[4])
def rows(mode):
    out = []
    for m, sps, elapsed, done, req, proc, total, render, wall, client in runs:
        if m == mode:
            out.append(dict(sps=float(sps), elapsed=float(elapsed), done=int(done), req=int(req), proc=float(proc), total=float(total),
                            render=float(render), wall=float(wall), client=float(client)))
    return out
quiet, polled = rows("quiet"), rows("polled")
med = lambda xs: statistics.median(xs)
q_sps, p_sps = med([r["sps"] for r in quiet]), med([r["sps"] for r in polled])
# samples/s from the film: pixels x samples per pixel / render time
q_film = med([size * size * r["done"] / r["elapsed"] for r in quiet])
p_film = med([size * size * r["done"] / r["elapsed"] for r in polled])
cost = 100 * (q_sps - p_sps) / q_sps
# tesserad's CPU outside its render threads: HTTP, scheduler, previews, checkpoints; the quiet rate is the baseline.
other_quiet_per_s = med([(r["total"] - r["render"]) / r["wall"] for r in quiet])
requests = sum(r["req"] for r in polled)
net_ms = sum((r["total"] - r["render"]) - other_quiet_per_s * r["wall"] for r in polled)
per_req = net_ms / requests if requests else float("nan")
gross_per_req = sum(r["total"] - r["render"] for r in polled) / requests if requests else float("nan")
client_per_req = sum(r["client"] for r in polled) / requests if requests else float("nan")
print()
print("quiet   samples/s  median %.4g (film: %.4g) over %d renders: %s" % (q_sps, q_film, len(quiet),
      ", ".join("%.4g" % r["sps"] for r in quiet)))
print("polled  samples/s  median %.4g (film: %.4g) over %d renders: %s" % (p_sps, p_film, len(polled),
      ", ".join("%.4g" % r["sps"] for r in polled)))
print("throughput cost    %.2f %% (goal: at most 5 %%)" % cost)
print("requests served    %d in %.1f s of polled renders (%.0f requests/s)" % (requests,
      sum(r["wall"] for r in polled), requests / sum(r["wall"] for r in polled)))
print("tesserad CPU       %.3f ms a status request (%.3f ms before taking off the quiet non-render baseline, %.1f ms/s)"
      % (per_req, gross_per_req, other_quiet_per_s))
print("poll-load CPU      %.3f ms a request" % client_per_req)
print("at %.0f requests/s tesserad takes %.1f %% of %d cores; the load program %.1f %%" % (rate,
      100 * per_req * rate / 1000 / cores, cores, 100 * client_per_req * rate / 1000 / cores))
PY
