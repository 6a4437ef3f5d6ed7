#!/usr/bin/env bash
# Quick start, the main job: install what is missing, build, and start the rendering server
# on the built-in demo volume. Open the printed URL in a browser, or drive it with a script
# (client/python/examples/orbit.py, build/client/volcast-client). Ctrl-C stops it.
#
# Settings come from the environment (server/README.md lists them all), e.g.
#   VOLCAST_PORT=9000 VOLCAST_DATA=/scans deploy/run.sh
set -euo pipefail
cd "$(dirname "$0")/.."
deploy/install.sh
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build build -j"$(nproc)" --target volcast-server volcast-client
host="${VOLCAST_BIND:-127.0.0.1}"
[ "$host" = "0.0.0.0" ] && host=127.0.0.1
echo "volcast: starting the server at http://${host}:${VOLCAST_PORT:-8080}/ (WebSocket /ws; Ctrl-C stops it)"
exec build/server/volcast-server --web-root "$(pwd)/web" "$@"
