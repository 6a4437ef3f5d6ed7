#!/usr/bin/env bash
# Bundle volcast's renderer binaries for a GPU machine without our build dependencies: relinks
# volcast-render, volcast-bench, volcast_renderer_tests and volcast-stability from an existing
# Release build without OpenImageIO (images are written as raw float RGBA, see image_stub.cpp),
# gathers the shared libraries they need (ITK, GDCM, Highway, spdlog, the OpenCL ICD loader)
# into DEST/pkg.tar.xz (about 8 MB) and copies run-on-device.sh beside it (README.md).
#
#   tests/device/make-bundle.sh build .device-bundle               # from the project's root
#   echo /.device-bundle/ >> .git/info/exclude                     # once: keep it out of git
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
build=$(cd "${1:-build}" && pwd)
dest=${2:-.device-bundle}
src=$(pwd)
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
mkdir -p "$dest" "$work/pkg/bin" "$work/pkg/lib"
g++ -std=c++20 -O2 -c -I"$src" "$here/image_stub.cpp" -o "$work/image_stub.o"
for spec in renderer:volcast-render tests/bench:volcast-bench tests:volcast_renderer_tests tests/stability:volcast-stability; do
  dir=${spec%%:*}; name=${spec#*:}
  link="$build/$dir/CMakeFiles/$name.dir/link.txt"
  [ -f "$link" ] || { echo "skip $name: no $link (build it first)"; continue; }
  # image_stub.o stands for the whole image-file library: the library's object would otherwise
  # still be pulled in (for a symbol besides the two the stub defines) and with it OpenImageIO.
  cmd=$(sed -e 's|[^ ]*libOpenImageIO\(_Util\)\?\.so[^ ]*||g' -e 's|[^ ]*libvolcast_image_files\.a||g' \
            -e "s| -o $name | -o $work/pkg/bin/$name $work/image_stub.o |" "$link")
  (cd "$build/$dir" && eval "$cmd")
  echo "linked $name"
done
# Every library the binaries need but glibc's and the C++ runtime's (the device has newer ones).
for b in "$work"/pkg/bin/*; do ldd "$b" | awk '{print $3}' | grep '^/' || true; done | sort -u |
  grep -v -E '/(libc|libm|libpthread|libdl|librt|libstdc\+\+|libgcc_s)\.so' |
  while read -r lib; do cp -L "$lib" "$work/pkg/lib/"; done
tar -C "$work/pkg" -cJf "$dest/pkg.tar.xz" .
cp "$here/run-on-device.sh" "$dest/"
# The scans Figure 5 and Table 1 read (2.7 + 3.0 MB), from VOLCAST_DATA_DIR or ../shared.
data=${VOLCAST_DATA_DIR:-$src/../shared/data/volumes}
mkdir -p "$dest/data"
for f in bonsai.nhdr bonsai.raw.gz tooth.nhdr tooth.raw; do
  [ -f "$data/$f" ] && cp "$data/$f" "$dest/data/"
done
du -sh "$dest/pkg.tar.xz"
