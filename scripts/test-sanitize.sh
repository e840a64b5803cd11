#!/usr/bin/env bash
# Builds btfc with AddressSanitizer + UndefinedBehaviorSanitizer into build-asan/ and runs the
# whole test suite under it, once with OpenCL (PoCL) and once on the CPU path. PoCL's known
# exit-time leaks are suppressed by tests/lsan.supp, nothing of ours.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
B=build-asan
[ -f "$B/CMakeCache.txt" ] || cmake -S . -B "$B" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DBTFC_SANITIZE=ON -DBTFC_BUILD_BENCH=OFF >/dev/null
cmake --build "$B" -j "$(nproc)"
export ASAN_OPTIONS=detect_leaks=1:abort_on_error=0
export LSAN_OPTIONS=suppressions=$PWD/tests/lsan.supp
export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
cd "$B"
ctest --output-on-failure -j "$(nproc)" "$@"
BTFC_FORCE_CPU=1 ctest --output-on-failure -j "$(nproc)" "$@"
