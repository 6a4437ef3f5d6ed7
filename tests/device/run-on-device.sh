#!/bin/bash
# Runs on a GPU machine (an NVIDIA card and driver, no build dependencies): volcast's OpenCL path on
# the GPU through NVIDIA's OpenCL driver, and the native path on that machine's cores.
# Everything it prints goes to the log; result files go to $OUT/res.tgz. Each step is bounded.
# Usage there: bash .device-bundle/run-on-device.sh [STEP...]
# STEPs: tests rounding table1 prefilter figure5 ladder cpu (default: all, in that order; about 2 minutes).
# `rounding` reruns the device-sensitive cases with each liberty OpenCL C gives a device taken
# away in turn (division, contraction, denormals, the cubic spline from hardware-filtered fetches).
cd "$(dirname "$0")"
R=/tmp/volcast-device-results; rm -rf "$R"; mkdir -p "$R" /tmp/volcast-device
[ -x /tmp/volcast-device/bin/volcast-bench ] || tar -C /tmp/volcast-device -xJf pkg.tar.xz
export LD_LIBRARY_PATH=/tmp/volcast-device/lib
nv=$(ls /usr/local/nvidia/lib64/libnvidia-opencl.so.1 /usr/lib/x86_64-linux-gnu/libnvidia-opencl.so.1 2>/dev/null | head -1)
[ -z "$nv" ] && nv=$(find / -xdev -name 'libnvidia-opencl.so.1' 2>/dev/null | head -1)
[ -z "$nv" ] && { echo "no libnvidia-opencl.so.1 on this machine"; exit 1; }
mkdir -p /tmp/volcast-icd; echo "$nv" > /tmp/volcast-icd/nvidia.icd; export OCL_ICD_VENDORS=/tmp/volcast-icd
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader
echo "CPU: $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2)"
B=/tmp/volcast-device/bin; export VOLCAST_DEVICE=gpu
steps=${*:-tests rounding table1 prefilter figure5 ladder cpu}
sensitive='*CamerasAndRays_OpenCl*:*DegenerateVolumes_OpenCl*:CpuRenderer.DrawsTheOpenClImageToFloatRounding:DeviceRounding.*'
t0=$SECONDS
for s in $steps; do
  echo "=== $s (at $((SECONDS - t0)) s)"
  case $s in
    tests)     timeout 180 $B/volcast_renderer_tests --gtest_brief=1 --gtest_filter='-VolumeIo*' > $R/tests.log 2>&1; echo "rc=$?"
               grep -E '^\[  (FAILED|PASSED)|FAILED TESTS|Failure' $R/tests.log | head -40 ;;
    rounding)  for v in "plain|" "divide|VOLCAST_OPENCL_OPTIONS=-cl-fp32-correctly-rounded-divide-sqrt" \
                        "contract|VOLCAST_OPENCL_OPTIONS=-DVC_FP_CONTRACT_OFF" "denorms|VOLCAST_OPENCL_OPTIONS=-cl-denorms-are-zero" \
                        "taps64|VOLCAST_CUBIC_FETCH=taps64" "image|VOLCAST_CUBIC_FETCH=image"; do
                 name=${v%%|*}; setting=${v#*|}
                 env $setting timeout 60 $B/volcast_renderer_tests --gtest_brief=1 --gtest_filter="$sensitive" > $R/rounding-$name.log 2>&1
                 echo "--- $name ($setting): rc=$? $(grep -c '^\[  FAILED  \]' $R/rounding-$name.log) failed"
                 grep -E 'worst|bound|off by|Expected|Which is' $R/rounding-$name.log | head -8
               done ;;
    table1)    timeout 120 $B/volcast-bench table1 --backend opencl --device gpu --data data --repeats 10 --out $R/table1-gpu 2>&1 | tail -9 ;;
    prefilter) timeout 150 $B/volcast-bench prefilter --device gpu --out $R/prefilter-gpu 2>&1 | tail -6 ;;
    figure5)   timeout 150 $B/volcast-bench figure5 --backends opencl --device gpu --data data --out $R/figure5-gpu 2>&1 | tail -9 ;;
    ladder)    timeout 120 $B/volcast-bench ladder --backend opencl --device gpu --data data --out $R/ladder-gpu 2>&1 | tail -14 ;;
    cpu)       timeout 120 $B/volcast-bench table1 --backend cpu --data data --repeats 10 --out $R/table1-cpu 2>&1 | tail -9 ;;
    *)         echo "unknown step $s" ;;
  esac
done
echo "=== done in $((SECONDS - t0)) s"
tar -czf "${OUT:-.}/res.tgz" -C "$R" .
