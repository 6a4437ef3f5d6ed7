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
# The fuzz targets, built by clang in a tree of their own (fuzz/README.md); each runs for a
# short fixed time over its committed corpus, so a regression in a parser is caught.
cmake -S . -B build-fuzz -DCMAKE_CXX_COMPILER=clang++-14 -DCMAKE_C_COMPILER=clang-14 \
  -DVOLCAST_FUZZ=ON -DVOLCAST_BUILD_TESTS=OFF >/dev/null
cmake --build build-fuzz -j"$(nproc)" --target fuzz_targets
ctest --test-dir build-fuzz -L fuzz --output-on-failure -j"$(nproc)"
