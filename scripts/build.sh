#!/usr/bin/env bash
# Configures and builds btfc into build/ (Release). Used by test.sh and run-demo.sh.
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD_DIR=${BTFC_BUILD_DIR:-build}
# ccache (installed by setup.sh) when present: test.sh builds two trees (this one and the
# sanitizer tree), and a re-run or a fresh clone of the same sources then recompiles only what
# changed. Paths are hashed relative to the checkout (CCACHE_BASEDIR) and without the working
# directory (CCACHE_NOHASHDIR: the sanitizer tree's line tables), so any clone shares the cache.
# BTFC_CCACHE=0 turns it off.
LAUNCHER=()
if [ "${BTFC_CCACHE:-1}" != 0 ] && command -v ccache >/dev/null; then
  LAUNCHER=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache -DCMAKE_C_COMPILER_LAUNCHER=ccache)
  export CCACHE_BASEDIR=${CCACHE_BASEDIR:-$PWD} CCACHE_NOHASHDIR=1
fi
if [ ! -f "$BUILD_DIR/CMakeCache.txt" ]; then
  # BTFC_CMAKE_ARGS: extra configure arguments.
  # shellcheck disable=SC2086
  cmake -S . -B "$BUILD_DIR" -DCMAKE_BUILD_TYPE=Release "${LAUNCHER[@]}" ${BTFC_CMAKE_ARGS:-} >/dev/null
fi
cmake --build "$BUILD_DIR" -j "$(nproc)"
