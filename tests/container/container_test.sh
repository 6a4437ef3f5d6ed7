#!/usr/bin/env bash
# The container service, built and run here (deploy/README.md). One command, as root, from a
# fresh clone on Debian 12 (deploy/install.sh installs podman, podman-compose, debootstrap, curl):
#
#   tests/container/container_test.sh
#
# 1. Builds deploy/Containerfile with podman (build_image.sh: base image by debootstrap).
# 2. `podman run` with the port published on 127.0.0.1 and a read-only data folder holding a
#    small scan: /healthz, /readyz, /metrics, the image's HEALTHCHECK, non-root, PID 1, /data
#    read-only, a WebSocket session to a final frame of the scan; then `podman stop`: the open
#    session gets close 1001 naming SIGTERM and the container exits 0 within its grace period.
# 3. `podman kube play` of deploy/k8s/deployment.yaml (image, claim, one replica and a
#    loopback host port swapped in for the test's): the same checks against the pod, with its
#    read-only root file system and POCL_MAX_PTHREAD_COUNT from the CPU limit.
# 4. deploy/compose.yaml with podman-compose (where installed): the same checks, then `down`.
#
# Prints the figures deploy/README.md reports (image size, build and start-up times) and keeps
# them in $VOLCAST_CONTAINER_WORK/figures.txt. Exits 77 (CTest: skipped) only where podman
# cannot run containers for a reason no install fixes: not root, or inside a container. A tool
# deploy/install.sh installs (podman, runc, catatonit, debootstrap, curl) that is missing fails
# the test, naming it. Every failure prints its reason, and the tail of podman's log, here.
# Environment:
# VOLCAST_CONTAINER_WORK (default /var/tmp/volcast-container), JOBS (compile jobs, default 2),
# VOLCAST_CONTAINER_SKIP_BUILD=1 (test the image built last instead of building it).
set -Eeuo pipefail
here=$(cd "$(dirname "$0")" && pwd)
repo=$(cd "$here/../.." && pwd)

skip() { echo "container test SKIPPED: $*" >&2; exit 77; }
[ "$(id -u)" = 0 ] || skip "needs root (rootful podman)"
# podman marks its containers so; nested podman fails there. Not /.dockerenv: this sandbox has
# one, and podman works in it.
if [ -e /run/.containerenv ]; then
  skip "running inside a podman container, where podman cannot start containers of its own"
fi
# Not skips: deploy/install.sh installs these, so a missing one is a broken install.
missing=()
for tool in podman runc debootstrap curl; do
  command -v "$tool" >/dev/null 2>&1 || missing+=("$tool")
done
# The pods' pause binary (`podman kube play`); podman looks in /usr/libexec/podman first.
[ -x /usr/libexec/podman/catatonit ] || command -v catatonit >/dev/null 2>&1 || missing+=(catatonit)
if [ ${#missing[@]} -gt 0 ]; then
  echo "container_test: FAILED: not installed: ${missing[*]} (run deploy/install.sh as root)" >&2
  exit 1
fi

. "$here/podman_env.sh"
work=$VOLCAST_CONTAINER_WORK
image=localhost/volcast:latest
name=volcast-test-$$
claim=volcast-test-data-$$
project=volcast-test-compose-$$
# podman's own complaints go here (without systemd it cannot time HEALTHCHECKs and says so on
# every start and stop); shown when something fails.
podman_log=$work/podman.log
: > "$podman_log"
log() { echo "container_test: $*"; }
fail() {
  trap - ERR
  echo "container_test: podman's log ($podman_log), last 20 lines:" >&2
  tail -20 "$podman_log" >&2
  echo "container_test: FAILED: $*" >&2
  exit 1
}
# Any other failing command (set -e) still says which one it was and why before the exit.
on_error() {
  local rc=$? line=$1 command=$2
  [ "$BASH_SUBSHELL" = 0 ] || return 0  # the command substitution's caller reports it
  fail "line $line exited $rc: $command"
}
trap 'on_error $LINENO "$BASH_COMMAND"' ERR
cleanup() {
  podman rm -f -t 0 "$name" >/dev/null 2>&1 || true
  [ -f "$work/deployment.yaml" ] && podman kube down "$work/deployment.yaml" >/dev/null 2>&1 || true
  podman volume rm -f "$claim" >/dev/null 2>&1 || true
  if command -v podman-compose >/dev/null 2>&1; then
    podman-compose -p "$project" -f "$repo/deploy/compose.yaml" down >/dev/null 2>&1 || true
    podman volume rm -f "${project}_kernel-cache" >/dev/null 2>&1 || true
  fi
}
trap cleanup EXIT

# ---- 1. build ------------------------------------------------------------------------
SECONDS=0
if [ "${VOLCAST_CONTAINER_SKIP_BUILD:-0}" = 1 ] && podman image exists "$image"; then
  log "VOLCAST_CONTAINER_SKIP_BUILD=1: testing the image built last"
else
  "$here/build_image.sh" "$image"
fi
build_s=$SECONDS
size_mb=$(( $(podman image inspect --format '{{.Size}}' "$image") / 1000000 ))
log "image $image: ${size_mb} MB, built in ${build_s} s"

# A small scan for the read-only data folder: an 8³ uint8 ramp, NRRD with attached raw data.
data=$work/data
rm -rf "$data" && mkdir -p "$data"
/usr/bin/python3 - "$data/tiny.nrrd" <<'PY'
import sys
header = b"NRRD0004\ntype: uint8\ndimension: 3\nsizes: 8 8 8\nspacings: 1 1 1\nencoding: raw\n\n"
voxels = bytes((x * 32 + y * 4 + z) % 256 for z in range(8) for y in range(8) for x in range(8))
open(sys.argv[1], "wb").write(header + voxels)
PY
chmod -R a+rX "$data"

# Poll URL until it answers 200; prints the seconds since $2 (a date +%s.%N stamp).
wait_ready() {
  local url=$1 since=$2 deadline=$((SECONDS + 180))
  until curl -fsS --max-time 2 -o /dev/null "$url" 2>/dev/null; do
    [ $SECONDS -lt $deadline ] || return 1
    sleep 0.1
  done
  awk -v now="$(date +%s.%N)" -v since="$since" 'BEGIN { printf "%.1f", now - since }'
}

# The checks all three runs share: HTTP endpoints, user, PID 1, read-only data, a session.
check_service() {
  local base=$1 container=$2
  [ "$(curl -fsS "$base/healthz")" = ok ] || fail "/healthz did not answer ok"
  [ "$(curl -fsS "$base/readyz")" = ready ] || fail "/readyz did not answer ready"
  # Whole answers first: `grep -q` quitting early would fail the pipe under pipefail.
  local metrics page
  metrics=$(curl -fsS "$base/metrics") && grep -q '^volcast_sessions ' <<<"$metrics" || fail "/metrics has no volcast_sessions"
  page=$(curl -fsS "$base/") && grep -qi '<html' <<<"$page" || fail "/ does not serve the web client"
  [ "$(podman exec "$container" id -u)" = 10001 ] || fail "the server does not run as uid 10001"
  [ "$(podman exec "$container" cat /proc/1/comm)" = volcast-server ] || fail "PID 1 is not volcast-server"
  ! podman exec "$container" touch /data/written 2>/dev/null || fail "/data is writable"
  log "HTTP endpoints, non-root user, PID 1 and read-only /data: ok"
  /usr/bin/python3 "$here/session_check.py" "${base/http/ws}/ws" --volume tiny.nrrd ||
    fail "WebSocket session on the scan from /data"
  /usr/bin/python3 "$here/session_check.py" "${base/http/ws}/ws" || fail "WebSocket session on the default volume"
}

# ---- 2. podman run -------------------------------------------------------------------
port=$(/usr/bin/python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
t0=$(date +%s.%N)
podman run -d --name "$name" --pull=never -p "127.0.0.1:$port:8080" -v "$data:/data:ro" "$image" >/dev/null 2>>"$podman_log" ||
  fail "podman run"
run_ready_s=$(wait_ready "http://127.0.0.1:$port/readyz" "$t0") ||
  { podman logs "$name" | tail -20; fail "podman run: /readyz not 200 within 180 s"; }
log "podman run: ready ${run_ready_s} s after the run command (port 127.0.0.1:$port)"
check_service "http://127.0.0.1:$port" "$name"
podman healthcheck run "$name" >/dev/null || fail "the image's HEALTHCHECK does not pass"
log "HEALTHCHECK: healthy"
# The drain: podman stop sends SIGTERM and, after 10 s, SIGKILL (which would exit 137).
/usr/bin/python3 "$here/session_check.py" "ws://127.0.0.1:$port/ws" --stop "podman stop -t 10 $name >/dev/null 2>>$podman_log" --grace 10 ||
  fail "podman stop with a session open"
[ "$(podman inspect --format '{{.State.ExitCode}}' "$name")" = 0 ] || fail "the container did not exit 0 after SIGTERM"
grep -q 'stopping: server shutting down (SIGTERM)' <<<"$(podman logs "$name" 2>&1)" || fail "the log does not show the SIGTERM"
log "podman stop: session closed 1001, exit 0"
podman rm "$name" >/dev/null 2>>"$podman_log" || fail "podman rm"

# ---- 3. podman kube play -------------------------------------------------------------
# The manifest as written, but for the image (the test's build), the claim (a throw-away podman
# volume holding the same small scan), one replica (podman makes a pod per replica, all on
# one host) and a host port on loopback to reach it by.
kport=$(/usr/bin/python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
sed -e "s|^\( *image:\) volcast$|\1 $image|" -e "s|claimName: volcast-data$|claimName: $claim|" \
    -e "s|^  replicas: [0-9]*$|  replicas: 1|" \
    -e "s|^\( *\)containerPort: 8080$|&\n\1hostIP: 127.0.0.1\n\1hostPort: $kport|" \
  "$repo/deploy/k8s/deployment.yaml" > "$work/deployment.yaml"
grep -q "image: $image" "$work/deployment.yaml" && grep -q "claimName: $claim" "$work/deployment.yaml" &&
  grep -q "hostPort: $kport" "$work/deployment.yaml" && grep -q "^  replicas: 1$" "$work/deployment.yaml" ||
  fail "deployment.yaml no longer has the image, claim, replicas or containerPort lines this test rewrites"
podman volume create "$claim" >/dev/null 2>>"$podman_log" || fail "podman volume create $claim"
tar -C "$data" -c . | podman volume import "$claim" - 2>>"$podman_log" || fail "podman volume import $claim"
t0=$(date +%s.%N)
podman kube play --replace "$work/deployment.yaml" >/dev/null 2>>"$podman_log" || fail "podman kube play"
pod=$(podman pod ps --format '{{.Name}}' | grep '^volcast-pod' | head -1)
[ -n "$pod" ] || fail "podman kube play made no volcast pod"
server=$(podman ps --filter "pod=$pod" --format '{{.Names}}' | grep -- '-server$' | head -1)
[ -n "$server" ] || fail "no server container in $pod"
kube_ready_s=$(wait_ready "http://127.0.0.1:$kport/readyz" "$t0") ||
  { podman logs "$server" | tail -20; fail "kube play: /readyz not 200 within 180 s"; }
log "kube play: pod $pod ready ${kube_ready_s} s after the play command (port 127.0.0.1:$kport)"
[ "$(podman inspect --format '{{.HostConfig.ReadonlyRootfs}}' "$server")" = true ] || fail "the pod's root file system is writable"
[ "$(podman exec "$server" printenv POCL_MAX_PTHREAD_COUNT)" = 4 ] || fail "POCL_MAX_PTHREAD_COUNT is not the CPU limit (4)"
check_service "http://127.0.0.1:$kport" "$server"
/usr/bin/python3 "$here/session_check.py" "ws://127.0.0.1:$kport/ws" --stop "podman pod stop -t 60 $pod >/dev/null 2>>$podman_log" --grace 60 ||
  fail "podman pod stop with a session open"
[ "$(podman inspect --format '{{.State.ExitCode}}' "$server")" = 0 ] || fail "the pod's server did not exit 0 after SIGTERM"
log "kube play: session closed 1001, exit 0"
podman kube down "$work/deployment.yaml" >/dev/null 2>>"$podman_log" || fail "podman kube down"

# ---- 4. compose ----------------------------------------------------------------------
# deploy/compose.yaml as a user runs it (podman-compose; its image is the one built above).
if command -v podman-compose >/dev/null 2>&1; then
  cport=$(/usr/bin/python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
  export VOLCAST_SCANS=$data VOLCAST_HOST_PORT=$cport
  compose=(podman-compose -p "$project" -f "$repo/deploy/compose.yaml")
  t0=$(date +%s.%N)
  "${compose[@]}" up -d >>"$podman_log" 2>&1 || fail "podman-compose up"
  compose_ready_s=$(wait_ready "http://127.0.0.1:$cport/readyz" "$t0") || fail "compose: /readyz not 200 within 180 s"
  ccontainer=${project}_volcast_1
  log "compose: ready ${compose_ready_s} s after up (port 127.0.0.1:$cport)"
  [ "$(podman inspect --format '{{.HostConfig.ReadonlyRootfs}}' "$ccontainer")" = true ] || fail "compose: the root file system is writable"
  check_service "http://127.0.0.1:$cport" "$ccontainer"
  /usr/bin/python3 "$here/session_check.py" "ws://127.0.0.1:$cport/ws" --stop "${compose[*]} down >>$podman_log 2>&1" --grace 15 ||
    fail "podman-compose down with a session open"
  log "compose: session closed 1001 on down"
else
  log "compose: SKIPPED, podman-compose is not installed (deploy/install.sh installs it)"
fi

figures="image ${size_mb} MB, build ${build_s} s, ready after podman run ${run_ready_s} s, after kube play ${kube_ready_s} s, after compose up ${compose_ready_s:-skipped} s, whole test ${SECONDS} s ($(date -u +%F))"
echo "$figures" > "$work/figures.txt"
log "PASSED. $figures"
