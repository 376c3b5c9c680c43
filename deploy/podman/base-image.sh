#!/usr/bin/env bash
# Makes the base image `debian:bookworm` locally, for machines that reach Debian's package mirror but no image
# registry: debootstrap a minimal bookworm root file system into a cache folder, then `podman import` it.
#   deploy/podman/base-image.sh [CACHE_DIR]     (default: build/deploy-cache)
# Idempotent: does nothing when the image exists; reuses CACHE_DIR/bookworm-minbase.tar when it exists.
# Needs root (debootstrap), podman and debootstrap (`deploy/install-deps.sh deploy`).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
repo=$(cd "$here/../.." && pwd)
cache=${1:-$repo/build/deploy-cache}
image=${TESSERA_BASE_IMAGE:-debian:bookworm}
mirror=${TESSERA_DEBIAN_MIRROR:-}
export CONTAINERS_CONF=${CONTAINERS_CONF:-$here/containers.conf}

if podman image exists "$image"; then
  echo "base-image: $image exists"
  exit 0
fi

mkdir -p "$cache"
tarball=$cache/bookworm-minbase.tar
if [ ! -s "$tarball" ]; then
  rootfs=$cache/bookworm-rootfs
  rm -rf "$rootfs" "$tarball.part"
  echo "base-image: debootstrap --variant=minbase bookworm $rootfs ${mirror}"
  # shellcheck disable=SC2086  # the mirror is optional
  debootstrap --variant=minbase bookworm "$rootfs" $mirror >"$cache/debootstrap.log" 2>&1 || {
    tail -n 30 "$cache/debootstrap.log" >&2
    echo "base-image: debootstrap failed (log: $cache/debootstrap.log)" >&2
    exit 1
  }
  # Smaller image: no downloaded .debs or package lists (apt-get update runs in every build anyway).
  rm -rf "$rootfs"/var/cache/apt/archives/*.deb "$rootfs"/var/lib/apt/lists/*
  tar --numeric-owner -C "$rootfs" -cf "$tarball.part" .
  mv "$tarball.part" "$tarball"
  rm -rf "$rootfs"
fi
echo "base-image: podman import $tarball $image"
podman import --change 'CMD ["/bin/bash"]' "$tarball" "$image" >/dev/null
podman image exists "$image"
echo "base-image: $image ready"
