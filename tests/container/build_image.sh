#!/usr/bin/env bash
# Build volcast's container image (deploy/Containerfile) with podman on a machine that reaches
# no container registry: the Debian 12 base image is made here by debootstrap, from Debian's
# apt mirror, instead of being pulled. Where a registry is reachable, plain
#   docker build -f deploy/Containerfile -t volcast .
# does the same from docker.io's debian:bookworm-slim.
#
#   tests/container/build_image.sh [IMAGE]        (as root; default IMAGE localhost/volcast:latest)
#
# Environment: VOLCAST_CONTAINER_WORK (default /var/tmp/volcast-container) holds the base's
# root file system and containers.conf; JOBS (default 2) compile jobs in the build stage.
# The caller sources podman_env.sh for the same settings when running the image.
set -euo pipefail
repo=$(cd "$(dirname "$0")/../.." && pwd)
image=${1:-localhost/volcast:latest}
. "$repo/tests/container/podman_env.sh"

# The base: a minimal Debian 12 with the same apt sources as docker.io's debian:bookworm
# (bookworm, -updates, -security), so that both bases give the same packages.
if ! podman image exists "$VOLCAST_BASE_IMAGE"; then
  rootfs=$VOLCAST_CONTAINER_WORK/rootfs
  if [ ! -x "$rootfs/usr/bin/apt-get" ]; then
    echo "build_image: debootstrap bookworm (minbase) into $rootfs"
    rm -rf "$rootfs"
    nice -n 19 debootstrap --variant=minbase bookworm "$rootfs" http://deb.debian.org/debian \
      >"$VOLCAST_CONTAINER_WORK/debootstrap.log" 2>&1 ||
      { tail -20 "$VOLCAST_CONTAINER_WORK/debootstrap.log" >&2; exit 1; }
  fi
  rm -f "$rootfs/etc/apt/sources.list"
  cat > "$rootfs/etc/apt/sources.list.d/debian.sources" <<'SOURCES'
Types: deb
URIs: http://deb.debian.org/debian
Suites: bookworm bookworm-updates
Components: main
Signed-By: /usr/share/keyrings/debian-archive-keyring.gpg

Types: deb
URIs: http://deb.debian.org/debian-security
Suites: bookworm-security
Components: main
Signed-By: /usr/share/keyrings/debian-archive-keyring.gpg
SOURCES
  rm -rf "$rootfs"/var/lib/apt/lists/* "$rootfs"/var/cache/apt/archives/*.deb
  tar -C "$rootfs" -c . | podman import - "$VOLCAST_BASE_IMAGE" >/dev/null
  echo "build_image: base image $VOLCAST_BASE_IMAGE made"
fi

# --format docker keeps HEALTHCHECK (the OCI image format has no field for it).
SECONDS=0
nice -n 19 podman build --pull=never --format docker \
  --build-arg BASE="$VOLCAST_BASE_IMAGE" --build-arg JOBS="${JOBS:-2}" \
  -f "$repo/deploy/Containerfile" -t "$image" "$repo"
echo "build_image: $image built in ${SECONDS} s, $(podman image inspect --format '{{.Size}}' "$image") bytes"
