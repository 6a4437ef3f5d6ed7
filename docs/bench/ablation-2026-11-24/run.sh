#!/bin/bash
# Where the native path's time goes (docs/cpu_renderer.md, "What a step costs"):
# volcast-bench relinked with renderer/cpu/cpu_march.cpp changed one way at a time, then
# Table 1's 4 MiB cell at 512² timed for every variant in turn, ROUNDS rounds.
# Needs a Release build in build/ (README). Usage: run.sh [ROUNDS] [OUT]; TIME_ONLY=1 reuses
# the variants OUT already holds. Nothing else should run meanwhile (see `other load`).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
repo=$(cd "$here/../../.." && pwd)
rounds=${1:-3}
out=${2:-/tmp/volcast-ablation}
mkdir -p "$out"
B=$repo/build

variant() { # name, patch ('' for none), extra compiler flags
    local name=$1 patch=$2 flags=$3 dir=$out/bin/$1
    mkdir -p "$dir"
    git -C "$repo" show 7ebd2bf:renderer/cpu/cpu_march.cpp > "$dir/cpu_march.cpp" # the march the patches change
    [ -n "$patch" ] && patch -s "$dir/cpu_march.cpp" < "$here/$patch"
    # The copy includes itself through Highway's foreach_target: compile it in place of the original.
    cp "$dir/cpu_march.cpp" "$dir/cpu_march_variant.cpp"
    sed -i "s#\"renderer/cpu/cpu_march.cpp\"#\"$dir/cpu_march_variant.cpp\"#" "$dir/cpu_march_variant.cpp"
    c++ -DHWY_SHARED_DEFINE -I"$repo" -O3 -DNDEBUG -std=c++20 $flags -c "$dir/cpu_march_variant.cpp" -o "$dir/cpu_march.o"
    cp "$B/renderer/cpu/libvolcast_renderer_cpu.a" "$dir/libcpu.a"
    ar d "$dir/libcpu.a" cpu_march.cpp.o
    ar r "$dir/libcpu.a" "$dir/cpu_march.o" 2>/dev/null
    (cd "$B/tests/bench" && eval "$(sed "s# -o volcast-bench # -o $dir/volcast-bench #; s#../../renderer/cpu/libvolcast_renderer_cpu.a#$dir/libcpu.a#" CMakeFiles/volcast-bench.dir/link.txt)")
}

if [ -z "${TIME_ONLY:-}" ]; then
variant base '' ''
variant no-kahan ablation-macros.patch -DABL_NO_KAHAN
variant no-polynomial ablation-macros.patch -DABL_NO_POLY
variant reciprocal ablation-macros.patch -DABL_RECIP
variant no-colour ablation-macros.patch -DABL_NO_COLOR
variant no-arithmetic ablation-macros.patch '-DABL_NO_KAHAN -DABL_NO_POLY -DABL_RECIP'
variant branchless ablation-macros.patch -DABL_BRANCHLESS
variant always-colour ablation-macros.patch -DABL_ALWAYS_COLOR
variant always-exp ablation-macros.patch -DABL_ALWAYS_EXP
variant always-exact ablation-macros.patch -DABL_ALWAYS_EXACT
variant fake-sample ablation-macros.patch -DABL_FAKE_SAMPLE
variant avx2 '' '-DHWY_DISABLED_TARGETS=(HWY_AVX3|HWY_AVX3_DL)'
variant one-division one-division-per-crossing.patch ''
variant two-packets two-packets-per-loop.patch ''
fi

names="base no-kahan no-polynomial reciprocal no-colour no-arithmetic branchless always-colour always-exp always-exact
       fake-sample avx2 one-division two-packets"
for r in $(seq 1 "$rounds"); do
    for v in $names; do
        "$out/bin/$v/volcast-bench" table1 --backend cpu --volumes small --sizes 512x512 --repeats 20 \
            --out "$out/r${r}_$v" > /dev/null 2>&1
        python3 -c "
import json, sys
c = json.load(open('$out/r${r}_$v/table1.json'))['cells'][0]
print('round $r %-18s median %6.2f ms  %5.2f ns per sample-core  %.0f samples  other load %.2f' % ('$v',
      c['render_ms']['median'], c['core_ns_per_sample'], c['rays_hit'] * c['mean_samples_per_ray'],
      c['cpus_busy_with_other_processes']))"
    done
done
