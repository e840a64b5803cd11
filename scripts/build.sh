#!/usr/bin/env bash
# Configures and builds btfc into build/ (Release). Used by test.sh and run-demo.sh.
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD_DIR=${BTFC_BUILD_DIR:-build}
if [ ! -f "$BUILD_DIR/CMakeCache.txt" ]; then
  # BTFC_CMAKE_ARGS: extra configure arguments (scripts/fresh-check.sh passes a compiler launcher).
  # shellcheck disable=SC2086
  cmake -S . -B "$BUILD_DIR" -DCMAKE_BUILD_TYPE=Release ${BTFC_CMAKE_ARGS:-} >/dev/null
fi
cmake --build "$BUILD_DIR" -j "$(nproc)"
