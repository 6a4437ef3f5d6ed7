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
# The fuzz targets' committed corpora (seeds and regression inputs) are replayed by the
# fuzz_corpus.* tests of this tree, each target's invariants checked (fuzz/README.md); fuzzing
# itself needs the clang tree, built apart (fuzz/run.sh).

stage install deploy/install.sh
stage configure configure_main
stage build cmake --build build -j"$(nproc)"
stage test ctest --test-dir build --output-on-failure -j"$(nproc)"
