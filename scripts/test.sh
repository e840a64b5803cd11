#!/usr/bin/env bash
# Set-up, configure, build and run the whole test suite (ctest) twice: once with OpenCL on
# PoCL (the kernels' path) and once forced to the CPU path (BTFC_FORCE_CPU=1), so both the
# kernels and their C++ references are exercised by every test.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
scripts/build.sh
BUILD_DIR=${BTFC_BUILD_DIR:-build}
cd "$BUILD_DIR"
echo "== pass 1: OpenCL (auto: PoCL when present)"
ctest --output-on-failure -j "$(nproc)" "$@"
echo "== pass 2: CPU path (BTFC_FORCE_CPU=1)"
BTFC_FORCE_CPU=1 ctest --output-on-failure -j "$(nproc)" "$@"
