#!/usr/bin/env bash
# The README's first command, for real, where a new user runs it: a bare Debian 12 (debootstrap `minbase`, the base
# image the other container tests make: no make, no compiler, no sudo) with a copy of the repository as a clone has
# it (the tracked files and new ones git does not ignore: no build trees, no node_modules). The README's first shell
# block runs as written, as root, until the daemon it starts answers GET /readyz; then the build must hold only the
# programs (no test suite configured), and `tessera submit --watch` renders a small job through it.
#   first_run_test.sh SOURCE_DIR BUILD_DIR
# Exit 0 passed, 1 failed, 77 skipped (no podman, or it cannot run a container here: `SKIPPED: reason`).
# Downloaded packages are kept in BUILD_DIR/deploy-cache/apt-archives between runs (apt still installs them all);
# the compiling is never cached. Prints how long installing and building took.
# Environment: TESSERA_FIRST_RUN_TIMEOUT (s, default 2700), the time the README's commands get to answer /readyz.
set -uo pipefail

test_name=first_run_test
# shellcheck source-path=SCRIPTDIR source=podman_env.sh
source "$(dirname "$0")/podman_env.sh"
deadline_s=${TESSERA_FIRST_RUN_TIMEOUT:-2700}

# --- the README's first shell block --------------------------------------------------------------------------------
awk '/^```sh$/ { inside = 1; next } inside && /^```$/ { exit } inside' "$src/README.md" >"$work/first.sh"
[ -s "$work/first.sh" ] || fail "README.md has no \`\`\`sh block"
say "the README's first commands:"
sed 's/^/    /' "$work/first.sh"

# --- a clone's files -------------------------------------------------------------------------------------------------
if git -C "$src" rev-parse --is-inside-work-tree >/dev/null 2>&1; then
  (cd "$src" && git ls-files -z --cached --others --exclude-standard |
     while IFS= read -r -d '' f; do [ -e "$f" ] && printf '%s\0' "$f"; done |
     tar --null -T - -cf "$work/src.tar") || fail "cannot pack the repository's files"
else
  tar -C "$src" --exclude='./build*' --exclude=node_modules --exclude=./data -cf "$work/src.tar" . \
    || fail "cannot pack $src"
fi
say "repository copy: $(tar -tf "$work/src.tar" | wc -l) files, $(( $(stat -c %s "$work/src.tar") / 1000000 )) MB"

# --- run it in a bare Debian -----------------------------------------------------------------------------------------
mkdir -p "$cache/apt-archives"
# Each command of the block is traced with the time it starts (bash -x), for the figures below.
cat >"$work/entry.sh" <<'EOF'
set -e
mkdir -p /root/tessera
tar -xf /mnt/src.tar -C /root/tessera
cd /root/tessera
{ echo 'PS4="+ [\$(date +%s)] "; set -x'; cat /mnt/first.sh; } >/tmp/first.sh
exec bash -e /tmp/first.sh
EOF
name=$tag-first
containers+=("$name")
start=$(date +%s)
timeout 120 podman run -d --name "$name" -v "$work/src.tar:/mnt/src.tar:ro" -v "$work/first.sh:/mnt/first.sh:ro" \
  -v "$work/entry.sh:/mnt/entry.sh:ro" -v "$cache/apt-archives:/var/cache/apt/archives" "$base" \
  bash /mnt/entry.sh >/dev/null 2>"$work/podman.err" || { cat "$work/podman.err"; fail "podman run failed"; }

# GET /readyz inside the container (the daemon listens on the container's loopback), with bash alone.
ready() {
  local status
  status=$(timeout 20 podman exec "$name" bash -c 'exec 3<>/dev/tcp/127.0.0.1/8080 || exit 1
    printf "GET /readyz HTTP/1.0\r\nHost: 127.0.0.1\r\n\r\n" >&3; head -n 1 <&3' 2>/dev/null)
  [[ $status == "HTTP/1."?" 200"* ]]
}
say "running them in $base (log: $cache/first-run.log; up to ${deadline_s}s)"
until ready; do
  if [ "$(podman inspect --format '{{.State.Running}}' "$name" 2>/dev/null)" != "true" ]; then
    podman logs "$name" >"$cache/first-run.log" 2>&1
    tail -n 40 "$cache/first-run.log"
    fail "the README's first commands ended (exit $(podman inspect --format '{{.State.ExitCode}}' "$name")) before the daemon was ready"
  fi
  if [ $(( $(date +%s) - start )) -ge "$deadline_s" ]; then
    podman logs "$name" >"$cache/first-run.log" 2>&1
    tail -n 40 "$cache/first-run.log"
    fail "the daemon did not answer /readyz within ${deadline_s}s"
  fi
  sleep 5
done
ready_at=$(date +%s)
podman logs "$name" >"$cache/first-run.log" 2>&1
# The start time of each traced command that is a line of the block: the installing ends where the next one starts.
times=$(sed -n 's/^+ \[\([0-9]*\)\] .*/\1/p' "$cache/first-run.log")
second=$(sed -n 2p <<<"$times")
if [ -n "$second" ]; then
  say "daemon ready after $(( ready_at - start ))s: $(( second - start ))s for the first command, $(( ready_at - second ))s for the rest"
else
  say "daemon ready after $(( ready_at - start ))s"
fi

# --- what it built, and a render through it --------------------------------------------------------------------------
in_container() { timeout 300 podman exec -w /root/tessera "$name" bash -c "$1"; }
cached=$(in_container 'sed -n "s/^TESSERA_BUILD_TESTS:BOOL=//p" build/CMakeCache.txt')
[ "$cached" = "OFF" ] || fail "the build directory was configured with the test suite (TESSERA_BUILD_TESTS='$cached')"
in_container 'test ! -e build/tests/renderer/renderer_unit_tests' || fail "the test suite was built"
in_container 'dpkg-query -W -f="\${Status}" libgtest-dev 2>/dev/null | grep -q "install ok installed"' \
  && fail "libgtest-dev was installed: running needs no test framework"
say "built the programs only (no test suite, no GTest)"
in_container 'build/clients/cli/tessera submit proto/examples/cornell.json --width 32 --height 32 --spp 4 --watch' \
  >"$work/submit.log" 2>&1 || { tail -n 20 "$work/submit.log"; fail "tessera submit --watch of a small Cornell box failed"; }
grep -q succeeded "$work/submit.log" || { cat "$work/submit.log"; fail "the job did not succeed"; }
say "tessera submit --watch: the Cornell box rendered by the daemon the README started"
say "all checks passed"
exit 0
