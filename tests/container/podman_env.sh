# Sourced by the container scripts: podman settings this kind of sandbox needs (docs/platform.md):
# it cannot raise ulimits, and crun fails on its hybrid cgroups, so runc with fixed limits.
# Harmless on an ordinary machine.
VOLCAST_CONTAINER_WORK=${VOLCAST_CONTAINER_WORK:-/var/tmp/volcast-container}
VOLCAST_BASE_IMAGE=${VOLCAST_BASE_IMAGE:-localhost/volcast-base:bookworm}
mkdir -p "$VOLCAST_CONTAINER_WORK"
cat > "$VOLCAST_CONTAINER_WORK/containers.conf" <<'CONF'
[containers]
default_ulimits = ["nofile=1024:1024", "nproc=4096:4096"]
[engine]
runtime = "runc"
CONF
export CONTAINERS_CONF=$VOLCAST_CONTAINER_WORK/containers.conf
