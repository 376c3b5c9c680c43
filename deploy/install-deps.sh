#!/usr/bin/env bash
# Installs what tessera needs to build, run and test on Debian 12, idempotently: nothing is installed twice and a
# machine that has everything is left alone. It needs only bash and apt, so it is the first command on a fresh
# machine (make included). Runs apt-get as root, or through sudo when not root.
# Usage: deploy/install-deps.sh [build|test|deploy]
#   build   (the default) make, the toolchain and libraries to build and run tessera
#   test    build + what the test suite needs, the deployment tests' tools included (below)
#   deploy  the tools of deploy/: podman (with runc) and debootstrap to build and run the container image without a
#           registry (deploy/podman/), systemd's systemd-analyze for the unit, dpkg-dev for `cpack -G DEB`
set -euo pipefail
mode=${1:-build}
case "$mode" in
  build|test|deploy) ;;
  *) echo "usage: deploy/install-deps.sh [build|test|deploy]" >&2; exit 2 ;;
esac
cd "$(dirname "$0")/.."

SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi

packages=(
  make build-essential cmake ninja-build pkg-config git ca-certificates curl python3
  libembree-dev libopenimageio-dev openimageio-tools libcpp-httplib-dev nlohmann-json3-dev libtinygltf-dev
  libsqlite3-dev libpq-dev libtbb-dev libssl-dev libstb-dev libjpeg-dev libdraco-dev libmeshoptimizer-dev
  libseccomp-dev libeigen3-dev libmurmurhash-dev libopenvdb-dev libboost-iostreams-dev
)
if [ "$mode" = "test" ]; then
  # postgresql: the server the job-store tests start their throw-away clusters with (initdb, pg_ctl).
  # clang-format: the test that the tracked sources are formatted as .clang-format says (Debian 12's, version 14).
  # clang-14, libfuzzer-14-dev, libclang-rt-14-dev: the fuzz targets of tests/fuzz (build-fuzz); the last holds the
  # runtimes of -fsanitize=fuzzer,address,undefined, which clang-14 only recommends (not installed here).
  packages+=(libgtest-dev libgmock-dev libbenchmark-dev chromium prometheus postgresql clang-format
             clang-14 libfuzzer-14-dev libclang-rt-14-dev)
  # Node.js: any working node and npm will do (machines often have a newer one than Debian's, which Debian's npm
  # package would conflict with); Debian's only when there is none.
  if ! command -v node >/dev/null 2>&1 || ! command -v npm >/dev/null 2>&1; then packages+=(nodejs npm); fi
fi
if [ "$mode" = "test" ] || [ "$mode" = "deploy" ]; then
  packages+=(podman runc debootstrap uidmap slirp4netns fuse-overlayfs netavark aardvark-dns iptables
             systemd dpkg-dev python3-yaml)
fi

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then missing+=("$p"); fi
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "install-deps: installing ${missing[*]}"
  if [ -n "$SUDO" ] && ! command -v sudo >/dev/null 2>&1; then
    echo "install-deps: installing packages needs root: run this as root, or install sudo first" >&2
    exit 1
  fi
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get update -qq
  $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
else
  echo "install-deps: all Debian packages present"
fi

# npm packages for the contract and browser tests live in tests/js (a package.json with a lock file).
if [ "$mode" = "test" ] && [ -f tests/js/package.json ]; then
  if [ ! -d tests/js/node_modules ] || [ tests/js/package-lock.json -nt tests/js/node_modules/.stamp ]; then
    echo "install-deps: npm packages for tests/js"
    (cd tests/js && npm ci --no-audit --no-fund --loglevel=error && touch node_modules/.stamp)
  fi
fi
# The deployment tests' validators (Kubernetes and Compose schemas) live in tests/deploy.
if [ "$mode" = "test" ] && [ -f tests/deploy/package-lock.json ]; then
  if [ ! -d tests/deploy/node_modules ] || [ tests/deploy/package-lock.json -nt tests/deploy/node_modules/.stamp ]; then
    echo "install-deps: npm packages for tests/deploy"
    (cd tests/deploy && npm ci --no-audit --no-fund --loglevel=error && touch node_modules/.stamp)
  fi
fi
