#!/usr/bin/env bash
# Installs the Debian packages btfc needs. Idempotent: does nothing when all are present.
# Package list: ../shared/spec/toolchain.md section 1 (+ nlohmann-json, libdeflate for the CRC-32 of .btfc reads, scikit-image for the
# SSIM reference script and python3-sklearn for bench/peer_sklearn.sh (issue 24), GoogleTest / Google Benchmark; headless EGL + GLES on Mesa's llvmpipe and
# glslang for the export checks, toolchain.md section 7; pybind11 and pytest for the Python module;
# cpp-httplib for `btfc view` and chromium for the web viewer's browser test, issue 21; clang-14
# with libFuzzer and the sanitizer runtimes, and clang's OpenMP, for the ASan + UBSan pass and the
# fuzz smoke of scripts/test.sh (issue 25); ccache, so the second build tree and re-runs
# recompile only what changed).
set -euo pipefail
PACKAGES=(
  build-essential cmake
  libeigen3-dev libopenexr-dev libopenimageio-dev openimageio-tools
  pocl-opencl-icd ocl-icd-opencl-dev opencl-headers opencl-clhpp-headers clinfo
  libceres-dev libopenblas-dev zlib1g-dev libbz2-dev libzstd-dev libdeflate-dev libcli11-dev nlohmann-json3-dev
  libgtest-dev libgmock-dev libbenchmark-dev
  python3-numpy python3-skimage python3-matplotlib python3-sklearn
  pybind11-dev python3-dev python3-pytest
  libopenmpi-dev openmpi-bin
  libegl-mesa0 libgl1-mesa-dri libegl-dev libgles-dev glslang-tools
  libcpp-httplib-dev chromium
  clang-14 libclang-rt-14-dev libomp-14-dev ccache
)
missing=()
for p in "${PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  exit 0
fi
echo "setup: installing ${missing[*]}" >&2
SUDO=""
[ "$(id -u)" -ne 0 ] && SUDO="sudo"
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
