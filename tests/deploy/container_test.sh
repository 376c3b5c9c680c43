#!/usr/bin/env bash
# The container, for real: builds deploy/Dockerfile with podman, runs the image on a random loopback port with a
# named data volume, waits for /readyz, renders the Cornell box (64x64, 16 spp) over HTTP, fetches result.png and
# checks it, checks the image's HEALTHCHECK, user and clean SIGTERM stop, then runs a second container on the same
# volume with bearer tokens from a mounted file and finds the finished job and its PNG again. Before all that,
# tessera-render in the image (built for any x86-64) and in BUILD_DIR render the same films to the bit.
#   container_test.sh SOURCE_DIR BUILD_DIR
# Exit 0 passed, 1 failed, 77 skipped (podman missing or unable to run a container here: the reason is printed as
# `SKIPPED: ...`). Podman runs with deploy/podman/containers.conf (runtime runc, lowered ulimits); the base image
# debian:bookworm is made locally with deploy/podman/base-image.sh (debootstrap, cached in BUILD_DIR/deploy-cache).
# Environment: TESSERA_CONTAINER_IMAGE (default localhost/tessera:ctest), TESSERA_CONTAINER_BUILD_TIMEOUT (s, 1500).
set -uo pipefail

test_name=container_test
# shellcheck source-path=SCRIPTDIR source=podman_env.sh
source "$(dirname "$0")/podman_env.sh"

# --- the image ---------------------------------------------------------------------------------------------------
say "building $image from deploy/Dockerfile (log: $cache/podman-build.log)"
start=$(date +%s)
if ! timeout "$build_timeout" podman build --format docker --layers --pull=never -f "$src/deploy/Dockerfile" \
       -t "$image" "$src" >"$cache/podman-build.log" 2>&1; then
  tail -n 40 "$cache/podman-build.log"
  fail "podman build failed or took more than ${build_timeout}s"
fi
say "image built in $(( $(date +%s) - start ))s: $(podman image inspect --format '{{.Size}}' "$image" | awk '{printf "%.0f MB", $1/1e6}')"
[ "$(podman image inspect --format '{{.Config.User}}' "$image")" = "10001:10001" ] || fail "the image does not run as 10001"
# Captured first: with pipefail, `grep -q` leaving early can make the writer die of SIGPIPE and fail the pipeline.
grep -q readyz <<<"$(podman image inspect --format '{{.Config.Healthcheck}}' "$image")" || fail "the image has no HEALTHCHECK on /readyz"

# --- the same film from the image's build and this build -----------------------------------------------------------
# The image is built for any x86-64, `make test` for this processor (TESSERA_ARCH): with no multiply-adds fused, a
# render's film is the same to the bit (what lets `tessera merge` combine parts rendered on different machines).
mkdir -p "$work/film" && chmod 0777 "$work/film"
cat >"$work/film/material.json" <<'EOF'
{"kind": "material", "render": {"width": 48, "height": 16, "spp": 4, "seed": 7},
 "materials": [{"type": "conductor", "metal": "gold", "roughness": 0.2}, {"type": "plastic", "roughness": 0.1},
               {"type": "dielectric", "roughness": 0.05}]}
EOF
python3 - "$src/proto/examples/cornell.json" >"$work/film/cornell.json" <<'EOF' || fail "cannot read proto/examples/cornell.json"
import json, sys
job = json.load(open(sys.argv[1]))
job.setdefault("render", {}).update(width=32, height=32, spp=4)
json.dump(job, sys.stdout)
EOF
arch=$(sed -n 's/^TESSERA_ARCH:[A-Z]*=//p' "$build/CMakeCache.txt" 2>/dev/null)
for job in material cornell; do
  timeout 120 podman run --rm --network none --entrypoint tessera-render -v "$work/film:/film" "$image" \
    render "/film/$job.json" -o "/film/$job-image.tfilm" --threads 2 -q >"$work/film.log" 2>&1 \
    || { cat "$work/film.log"; fail "tessera-render in the image failed on the $job job"; }
  timeout 120 "$build/clients/cli/tessera-render" render "$work/film/$job.json" -o "$work/film/$job-here.tfilm" \
    --threads 2 -q >"$work/film.log" 2>&1 || { cat "$work/film.log"; fail "this build's tessera-render failed on $job"; }
  cmp -s "$work/film/$job-image.tfilm" "$work/film/$job-here.tfilm" \
    || fail "the $job film of the image's build differs from this build's (TESSERA_ARCH='$arch')"
done
say "the image's build and this one (TESSERA_ARCH='$arch') render the same films to the bit"

# --- run it --------------------------------------------------------------------------------------------------------
volume=$tag-data
volumes+=("$volume")
timeout 60 podman volume create "$volume" >/dev/null || fail "cannot create volume $volume"

run_container() {  # NAME [PODMAN RUN OPTIONS...]: starts the image like a production deployment would, prints the host port
  local name=$1
  shift
  containers+=("$name")
  timeout 120 podman run -d --name "$name" -p 127.0.0.1::8080 -v "$volume:/var/lib/tessera" \
    --read-only --tmpfs /tmp --cap-drop ALL --security-opt no-new-privileges --stop-timeout 30 \
    -e TESSERA_THREADS=2 "$@" "$image" >/dev/null 2>>"$work/podman.err" || { cat "$work/podman.err"; fail "podman run $name failed"; }
  local hostport
  hostport=$(timeout 30 podman port "$name" 8080/tcp | head -n 1)
  [[ "$hostport" == 127.0.0.1:* ]] || fail "container port 8080 is not published on loopback: '$hostport'"
  echo "${hostport##*:}"
}

wait_ready() {  # NAME URL: /readyz answers 200 within 60 s
  local name=$1 url=$2 deadline=$(( $(date +%s) + 60 ))
  until curl -fsS -m 2 -o /dev/null "$url/readyz" 2>/dev/null; do
    if [ "$(podman inspect --format '{{.State.Running}}' "$name" 2>/dev/null)" != "true" ]; then
      podman logs "$name" 2>&1 | tail -n 20
      fail "$name exited before it was ready"
    fi
    [ "$(date +%s)" -lt "$deadline" ] || { podman logs "$name" 2>&1 | tail -n 20; fail "$url/readyz not ready in 60 s"; }
    sleep 0.5
  done
}

first=$tag-1
port=$(run_container "$first") || exit 1
url=http://127.0.0.1:$port
wait_ready "$first" "$url"
say "ready on $url"
grep -q "listening on http://0.0.0.0:8080" <<<"$(podman logs "$first" 2>&1)" || fail "tesserad did not print 'listening on http://0.0.0.0:8080'"
[ "$(timeout 30 podman exec "$first" id -u)" = "10001" ] || fail "tesserad does not run as uid 10001"
curl -fsS -m 5 -o /dev/null "$url/livez" || fail "/livez does not answer"
timeout 60 podman healthcheck run "$first" >/dev/null 2>&1 || fail "podman healthcheck run: the image's HEALTHCHECK is not healthy"
say "healthcheck healthy, uid 10001"

# The Cornell box job, small.
python3 - "$src/proto/examples/cornell.json" >"$work/job.json" <<'EOF' || fail "cannot read proto/examples/cornell.json"
import json, sys
job = json.load(open(sys.argv[1]))
job.setdefault("render", {}).update(width=64, height=64, spp=16)
json.dump(job, sys.stdout)
EOF
code=$(curl -sS -m 30 -o "$work/submit.json" -w '%{http_code}' -X POST -H 'Content-Type: application/json' \
       --data-binary @"$work/job.json" "$url/v1/jobs") || fail "POST /v1/jobs failed"
[ "$code" = "202" ] || { cat "$work/submit.json"; fail "POST /v1/jobs answered $code, not 202"; }
id=$(python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["id"])' "$work/submit.json") || fail "no job id"
say "job $id submitted"

deadline=$(( $(date +%s) + 300 ))
state=queued
while :; do
  curl -fsS -m 10 -o "$work/status.json" "$url/v1/jobs/$id" || fail "GET /v1/jobs/$id failed"
  state=$(python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["state"])' "$work/status.json")
  case "$state" in
    succeeded) break ;;
    failed|cancelled) cat "$work/status.json"; fail "job $id ended $state" ;;
  esac
  [ "$(date +%s)" -lt "$deadline" ] || { cat "$work/status.json"; fail "job $id still $state after 300 s"; }
  sleep 0.5
done
say "job $id succeeded"

check_png() {  # FILE: a 64x64 PNG
  python3 - "$1" <<'EOF'
import struct, sys
data = open(sys.argv[1], "rb").read()
if data[:8] != b"\x89PNG\r\n\x1a\n" or data[12:16] != b"IHDR":
    sys.exit("not a PNG")
w, h = struct.unpack(">II", data[16:24])
if (w, h) != (64, 64):
    sys.exit(f"PNG is {w}x{h}, not 64x64")
EOF
}
curl -fsS -m 30 -o "$work/result.png" "$url/v1/jobs/$id/result.png" || fail "GET result.png failed"
check_png "$work/result.png" || fail "result.png is not a 64x64 PNG"
say "result.png: 64x64 PNG, $(stat -c %s "$work/result.png") bytes"

# SIGTERM (podman stop) ends tesserad cleanly, well within the grace.
start=$(date +%s)
timeout 60 podman stop -t 30 "$first" >/dev/null 2>>"$work/podman.err" || { cat "$work/podman.err"; fail "podman stop failed"; }
exit_code=$(podman inspect --format '{{.State.ExitCode}}' "$first")
[ "$exit_code" = "0" ] || { podman logs "$first" 2>&1 | tail -n 10; fail "tesserad exited $exit_code on SIGTERM"; }
say "stopped by SIGTERM in $(( $(date +%s) - start ))s, exit code 0"

# A new container on the same volume (an upgrade), now with bearer tokens from a read-only mounted file (as the
# Kubernetes Secret is): the health endpoints and the HEALTHCHECK still answer without a token, the API wants one,
# and the admin token finds the job and its unchanged PNG.
token=ctest-admin-$(od -An -N16 -tx1 /dev/urandom | tr -d ' \n')
printf '[{"token": "%s", "name": "ctest", "role": "admin"}]\n' "$token" >"$work/tokens.json"
chmod 0644 "$work/tokens.json"
second=$tag-2
port=$(run_container "$second" -v "$work/tokens.json:/etc/tessera/tokens/tokens.json:ro" \
       -e TESSERA_TOKENS=/etc/tessera/tokens/tokens.json) || exit 1
url=http://127.0.0.1:$port
wait_ready "$second" "$url"
timeout 60 podman healthcheck run "$second" >/dev/null 2>&1 || fail "HEALTHCHECK unhealthy with tokens configured"
code=$(curl -sS -m 10 -o /dev/null -w '%{http_code}' "$url/v1/jobs/$id")
[ "$code" = "401" ] || fail "with tokens, GET /v1/jobs/$id without a token answered $code, not 401"
auth=(-H "Authorization: Bearer $token")
curl -fsS -m 10 "${auth[@]}" -o "$work/status2.json" "$url/v1/jobs/$id" || fail "the job is gone after a new container on the volume"
grep -q '"succeeded"' "$work/status2.json" || fail "the job is no longer succeeded on the volume"
curl -fsS -m 30 "${auth[@]}" -o "$work/result2.png" "$url/v1/jobs/$id/result.png" || fail "result.png gone after a new container"
cmp -s "$work/result.png" "$work/result2.png" || fail "result.png changed between containers"
say "a new container on the same volume, with tokens: health open, API 401 without a token, the job and the same PNG"
timeout 60 podman stop -t 30 "$second" >/dev/null 2>>"$work/podman.err" || true

# (podman without systemd logs errors about healthcheck timers to podman.err; `podman healthcheck run` above works.)
say "all checks passed"
exit 0
