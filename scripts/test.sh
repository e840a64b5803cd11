#!/usr/bin/env bash
# Set-up, configure, build and run the whole test suite (ctest) three times:
#   1. with OpenCL on PoCL (the kernels' path);
#   2. forced to the CPU path (BTFC_FORCE_CPU=1), so both the kernels and their C++ references
#      are exercised by every test. Tests labelled `once` (docs, packaging, the browser: they run
#      the same commands as pass 1, and what differs on the CPU path is covered by the codec
#      tests) are not repeated here;
#   3. under AddressSanitizer + UndefinedBehaviorSanitizer in its own tree, then every fuzz
#      target for a fixed number of runs (scripts/test-sanitize.sh; BTFC_SANITIZE_PASS=0 skips
#      it for a quick local run, CI never sets it).
# Extra arguments go to ctest in every pass, e.g. scripts/test.sh -R Golden.
set -euo pipefail
cd "$(dirname "$0")/.."
t0=$(date +%s)
scripts/setup.sh
scripts/build.sh
t1=$(date +%s)
BUILD_DIR=${BTFC_BUILD_DIR:-build}
(
  cd "$BUILD_DIR"
  echo "== pass 1: OpenCL (auto: PoCL when present)"
  ctest --output-on-failure -j "$(nproc)" "$@"
  echo "== pass 2: CPU path (BTFC_FORCE_CPU=1)"
  BTFC_FORCE_CPU=1 ctest --output-on-failure -j "$(nproc)" -LE once "$@"
)
t2=$(date +%s)
if [ "${BTFC_SANITIZE_PASS:-1}" != 0 ]; then
  scripts/test-sanitize.sh "$@"
fi
t3=$(date +%s)
echo "test.sh: set-up and build $((t1 - t0)) s, passes 1-2 $((t2 - t1)) s, sanitizer pass and fuzz smoke $((t3 - t2)) s"
