#!/usr/bin/env bash
# Quick start, the main job: install what is missing, build, and render the built-in demo
# volume with the exact reference renderer. (The rendering service will replace this with
# "start the server" once it exists.)
set -euo pipefail
cd "$(dirname "$0")/.."
deploy/install.sh
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build build -j"$(nproc)" --target volcast-render
mkdir -p out
build/renderer/volcast-render scenes/demo.json -o out/demo.png --reference
echo "volcast: demo volume rendered to $(pwd)/out/demo.png"
