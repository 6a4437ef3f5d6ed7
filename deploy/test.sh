#!/usr/bin/env bash
# Quick start, the tests: install what is missing, build everything, run every test.
# CI (.ci/run) runs exactly this; there, warnings are errors.
set -euo pipefail
cd "$(dirname "$0")/.."
deploy/install.sh
werror=OFF
[ -n "${CI:-}" ] && werror=ON
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release -DVOLCAST_WARNINGS_AS_ERRORS="$werror" >/dev/null
cmake --build build -j"$(nproc)"
ctest --test-dir build --output-on-failure -j"$(nproc)"
