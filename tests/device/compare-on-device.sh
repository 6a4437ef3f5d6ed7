#!/bin/bash
# Runs on a GPU machine: Table 1 on the GPU for two or more bundles (make-bundle.sh) taking turns,
# ROUNDS rounds (default 3), so a change is measured side by side on the same card within a minute.
# Usage there, from the project's root, the bundles beside it:
#   bash tests/device/compare-on-device.sh .device-bundle-before .device-bundle [...]
# Each bundle's pkg.tar.xz is unpacked to /tmp/volcast-compare/NAME (NAME: the bundle folder's name);
# the scans come from the first bundle holding data/. TABLE1_ARGS replaces the default cells
# (512x512 and 1920x1080, all three volumes, 20 repeats). Each run's tables are printed; its
# files go to $OUT/compare/NAME-ROUND, packed into $OUT/compare.tgz.
# READBACKS="direct counters-first pinned" runs each bundle once per read-back in every round
# (VOLCAST_OPENCL_READBACK, opencl_renderer.hpp's ReadBack), named NAME-READBACK; then one
# bundle is enough.
set -u
readbacks=${READBACKS:-}
[ $# -ge 2 ] || { [ $# -ge 1 ] && [ -n "$readbacks" ]; } || { echo "usage: $0 BUNDLE BUNDLE [...]  (or READBACKS=... $0 BUNDLE)"; exit 2; }
rounds=${ROUNDS:-3}
out=${OUT:-.}
args=${TABLE1_ARGS:---sizes 512x512,1920x1080 --repeats 20}
work=/tmp/volcast-compare; rm -rf "$work"; mkdir -p "$work" "$out/compare"
data=
for b in "$@"; do
  name=$(basename "$b")
  mkdir -p "$work/$name"
  if ! tar -C "$work/$name" -xJf "$b/pkg.tar.xz"; then echo "cannot unpack $b/pkg.tar.xz"; exit 1; fi
  [ -z "$data" ] && [ -d "$b/data" ] && data=$b/data
done
[ -n "$data" ] || { echo "no bundle holds data/ (the scans Table 1 reads)"; exit 1; }
nv=
for f in /usr/local/nvidia/lib64/libnvidia-opencl.so.1 /usr/lib/x86_64-linux-gnu/libnvidia-opencl.so.1; do
  [ -e "$f" ] && { nv=$f; break; }
done
[ -z "$nv" ] && nv=$(find / -xdev -name 'libnvidia-opencl.so.1' 2>/dev/null | head -1)
[ -z "$nv" ] && { echo "no libnvidia-opencl.so.1 on this machine"; exit 1; }
mkdir -p /tmp/volcast-icd; echo "$nv" > /tmp/volcast-icd/nvidia.icd; export OCL_ICD_VENDORS=/tmp/volcast-icd
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader
for r in $(seq 1 "$rounds"); do
  for b in "$@"; do
    name=$(basename "$b")
    for rb in ${readbacks:-default}; do
      label=$name; [ "$rb" = default ] || label=$name-$rb
      echo "=== $label, round $r (at $SECONDS s)"
      # shellcheck disable=SC2086  # TABLE1_ARGS is a list of options
      VOLCAST_OPENCL_READBACK=${rb/default/} LD_LIBRARY_PATH=$work/$name/lib timeout 90 \
        "$work/$name/bin/volcast-bench" table1 --backend opencl --device gpu \
        --data "$data" $args --out "$out/compare/$label-$r" 2>&1 | grep '^|'
    done
  done
done
tar -czf "$out/compare.tgz" -C "$out" compare && rm -rf "$out/compare"
