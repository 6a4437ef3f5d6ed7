#!/usr/bin/env bash
# Quick start, the tests: install what is missing, build everything, run every test.
# CI (.ci/run) runs exactly this; there, warnings are errors.
# Each stage prints how long it took, and a summary at the end, so a slow stage shows.
set -euo pipefail
cd "$(dirname "$0")/.."

stages=()
stage() {   # stage NAME COMMAND...: runs the command, records its duration
  local name=$1 start=$SECONDS
  shift
  echo "=== stage: $name"
  "$@"
  local took=$((SECONDS - start))
  stages+=("$(printf '%-22s %4d s' "$name" "$took")")
  echo "=== stage: $name took ${took} s"
}
summary() {
  echo "=== stage durations (total ${SECONDS} s)"
  printf '  %s\n' "${stages[@]}"
}
trap summary EXIT

werror=OFF
[ -n "${CI:-}" ] && werror=ON
configure_main() {
  cmake -S . -B build -DCMAKE_BUILD_TYPE=Release -DVOLCAST_WARNINGS_AS_ERRORS="$werror" >/dev/null
}
# The fuzz targets, built by clang in a tree of their own (fuzz/README.md): only the targets
# and the libraries they link (no tests, no tools); each runs for a short fixed time over its
# committed corpus, so a regression in a parser is caught.
configure_fuzz() {
  cmake -S . -B build-fuzz -DCMAKE_CXX_COMPILER=clang++-14 -DCMAKE_C_COMPILER=clang-14 \
    -DVOLCAST_FUZZ=ON -DVOLCAST_BUILD_TESTS=OFF >/dev/null
}

stage install deploy/install.sh
stage configure configure_main
stage build cmake --build build -j"$(nproc)"
stage test ctest --test-dir build --output-on-failure -j"$(nproc)"
stage fuzz-configure configure_fuzz
stage fuzz-build cmake --build build-fuzz -j"$(nproc)" --target fuzz_targets
stage fuzz-test ctest --test-dir build-fuzz -L fuzz --output-on-failure -j"$(nproc)"
