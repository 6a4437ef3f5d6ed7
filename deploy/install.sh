#!/usr/bin/env bash
# Installs every Debian package volcast's build, tests and tools need.
# Idempotent and non-interactive: safe to run on every quick-start command and in CI.
set -euo pipefail

packages=(
  # Toolchain
  cmake g++ make pkg-config git ca-certificates
  # Server: Boost.Beast/Asio (header-only in 1.81)
  libboost1.81-dev
  # Image files in and out (EXR, TIFF, PNG, JPEG)
  libopenimageio-dev
  # Frames on the wire: JPEG through libjpeg-turbo's TurboJPEG API, PNG through libpng
  libturbojpeg0-dev libpng-dev
  # Volume formats: ITK image IO (NRRD, MetaImage, NIfTI, DICOM through GDCM)
  libinsighttoolkit5-dev
  # JSON, command line, logging
  nlohmann-json3-dev libcli11-dev libspdlog-dev libfmt-dev
  # OpenCL: ICD loader, headers, PoCL as the CPU device
  ocl-icd-opencl-dev opencl-headers opencl-clhpp-headers pocl-opencl-icd
  # zlib: tests write gzip-encoded NRRD files of their own
  zlib1g-dev
  # Tests and benchmarks
  libgtest-dev libgmock-dev libbenchmark-dev python3 python3-websockets
  # Fuzz targets (fuzz/README.md): clang with libFuzzer, ASan and UBSan
  clang-14 libfuzzer-14-dev libclang-rt-14-dev
  # The Python client package (client/python): Frame.to_numpy decodes with numpy and Pillow;
  # its test installs the package offline into a venv with the system's setuptools and wheel.
  python3-numpy python3-pil python3-venv python3-setuptools python3-wheel
  # Web client tests: Debian's Chromium driven by playwright-core
  chromium
  # Container tests: podman with runc and netavark's bridge network (iptables),
  # podman-compose, debootstrap for the base image (no registry is reachable), curl.
  # podman's recommended packages are not installed (--no-install-recommends), so the ones
  # the tests use are named here: catatonit is the pause binary of every pod
  # (`podman kube play` fails without it).
  podman runc netavark iptables podman-compose debootstrap curl catatonit
  # Vectorised CPU ray casting: Highway's SIMD headers
  libhwy-dev
  # Bringing your own scan: libcurl for DICOMweb (TLS verified against the system's CA
  # store), libzip for an uploaded .zip of a DICOM series, and a real PACS for the tests:
  # Orthanc with its DICOMweb plugin (docs/data-sources.md)
  libcurl4-openssl-dev libzip-dev orthanc orthanc-dicomweb
  # SHA-256 of upload ids for the log (server/upload_ids.hpp): OpenSSL's libcrypto, which
  # libcurl already loads
  libssl-dev
)
# Node.js and npm only where the machine has none: a machine may already carry a newer Node.js
# (NodeSource's, which bundles npm), and Debian's npm package conflicts with it.
command -v node >/dev/null 2>&1 || packages+=(nodejs)
command -v npm >/dev/null 2>&1 || packages+=(npm)

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done

if [ ${#missing[@]} -gt 0 ]; then
  echo "install.sh: installing ${missing[*]}"
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq
  apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi
echo "install.sh: all ${#packages[@]} packages present"

# The npm packages of the browser tests (playwright-core) and of the manifest checks
# (kubernetes-models, js-yaml), at their lockfiles' versions.
repo="$(cd "$(dirname "$0")/.." && pwd)"
for folder in tests/web tests/container; do
  "$repo/tests/npm-ci.sh" "$repo/$folder"
done
