#!/usr/bin/env bash
# Runs one fuzz target over its committed seed corpus, with its dictionary when there is one.
#   fuzz/run.sh TARGET [libFuzzer options...]      e.g. fuzz/run.sh fuzz_frame -runs=1000000
# New inputs go to $FUZZ_WORK/TARGET (default /tmp/volcast-fuzz), never into fuzz/corpus;
# a crash leaves its input as $FUZZ_WORK/TARGET-crash-*. BUILD (default build-fuzz) is the
# clang build folder. Runs under nice (FUZZ_NICE, default 10): the machine is shared.
set -euo pipefail
cd "$(dirname "$0")/.."
target=$1
shift
build=${BUILD:-build-fuzz}
work=${FUZZ_WORK:-/tmp/volcast-fuzz}
mkdir -p "$work/$target"
dict=()
[ -f "fuzz/dictionaries/$target.dict" ] && dict=(-dict="fuzz/dictionaries/$target.dict")
export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1}
export LSAN_OPTIONS=${LSAN_OPTIONS:-suppressions=$PWD/fuzz/lsan.supp}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1}
exec nice -n "${FUZZ_NICE:-10}" "$build/fuzz/$target" -print_final_stats=1 -timeout=10 -rss_limit_mb=2048 "${dict[@]}" \
  -artifact_prefix="$work/$target-" "$@" "$work/$target" "fuzz/corpus/$target"
