# shellcheck shell=bash disable=SC2034  # sourced: the variables are used by the sourcing script
# Sourced by the container tests: settings, helpers, cleanup, and the check that podman can run a container here
# (else `SKIPPED: reason` and exit 77). Expects $test_name, and SOURCE_DIR BUILD_DIR as $1 $2.
#   CONTAINERS_CONF   deploy/podman/containers.conf unless set (runtime runc, lowered ulimits)
#   base image        debian:bookworm, made with deploy/podman/base-image.sh (debootstrap) when missing, the root
#                     file system cached in BUILD_DIR/deploy-cache
src=$(cd "${1:?usage: $test_name SOURCE_DIR BUILD_DIR}" && pwd)
build=$(mkdir -p "${2:?usage: $test_name SOURCE_DIR BUILD_DIR}" && cd "$2" && pwd)
cache=$build/deploy-cache
mkdir -p "$cache"
export CONTAINERS_CONF=${CONTAINERS_CONF:-$src/deploy/podman/containers.conf}
image=${TESSERA_CONTAINER_IMAGE:-localhost/tessera:ctest}
base=debian:bookworm
build_timeout=${TESSERA_CONTAINER_BUILD_TIMEOUT:-1500}
tag=tessera-ctest-$$
work=$(mktemp -d)
containers=()
volumes=()

skip() { echo "SKIPPED: $*"; exit 77; }
fail() { echo "FAIL: $*"; exit 1; }
say() { echo "$test_name: $*"; }

cleanup() {
  for c in "${containers[@]}"; do timeout 60 podman rm -f -v -t 5 "$c" >/dev/null 2>&1; done
  for v in "${volumes[@]}"; do timeout 60 podman volume rm -f "$v" >/dev/null 2>&1; done
  rm -rf "$work"
}
trap cleanup EXIT
trap 'exit 1' INT TERM

# --- can this machine run containers? ----------------------------------------------------------------------------
command -v podman >/dev/null || skip "podman is not installed (deploy/install-deps.sh deploy installs it)"
command -v curl >/dev/null || skip "curl is not installed"
command -v python3 >/dev/null || skip "python3 is not installed"
if ! timeout 120 podman info >"$work/info" 2>&1; then
  skip "podman info fails: $(grep -v '^$' "$work/info" | tail -n 1)"
fi
if ! timeout 60 podman image exists "$base"; then
  command -v debootstrap >/dev/null || skip "no image $base and no debootstrap to make it (no registry is reachable)"
  [ "$(id -u)" -eq 0 ] || skip "no image $base, and making it with debootstrap needs root"
  say "making the base image $base (debootstrap, cached in $cache)"
  if ! timeout 1200 "$src/deploy/podman/base-image.sh" "$cache" >"$work/base.log" 2>&1; then
    tail -n 20 "$work/base.log"
    skip "cannot make the base image $base with debootstrap (is Debian's mirror reachable?)"
  fi
fi
if ! out=$(timeout 180 podman run --rm "$base" /bin/sh -c 'echo container-ok' 2>&1) || [[ "$out" != *container-ok* ]]; then
  skip "podman cannot run a container here: $(printf '%s\n' "$out" | grep -v '^$' | tail -n 1)"
fi
say "podman $(podman version --format '{{.Client.Version}}' 2>/dev/null), runtime $(podman info --format '{{.Host.OCIRuntime.Name}}' 2>/dev/null)"

