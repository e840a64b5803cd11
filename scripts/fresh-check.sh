#!/usr/bin/env bash
# What CI on this machine can hide: a package installed by hand, an untracked file, a test that
# holds only for one CPU's or one BLAS kernel's rounding. This clones the committed tree (HEAD,
# not the working tree) into a temporary folder beside ../shared (so the tests find the shared
# data as in a real checkout), then runs the README's test command there with OpenBLAS forced to
# another core type (Haswell kernels instead of the SkylakeX ones btfc picks on AVX-512), and
# the whole suite once more with one thread (OpenMP and OpenBLAS).
#
#   scripts/fresh-check.sh            # clone HEAD, build from scratch, 3 passes
#   KEEP=1 scripts/fresh-check.sh     # keep the clone (its path is printed)
#   CORETYPE=Zen scripts/fresh-check.sh
#   CCACHE=1 scripts/fresh-check.sh   # reuse the developer's ccache for the build
set -euo pipefail
cd "$(dirname "$0")/.."
SRC=$(pwd)
PARENT=$(dirname "$SRC")
[ -d "$PARENT/shared" ] || echo "fresh-check: no $PARENT/shared: data-dependent tests will skip" >&2
# The clone itself sits beside ../shared, as a checkout does: its tests read ../shared/data.
DIR=$(mktemp -d "$PARENT/btfc-fresh-XXXXXX")
cleanup() { [ "${KEEP:-0}" = 1 ] && echo "fresh-check: kept $DIR" || rm -rf "$DIR"; }
trap cleanup EXIT
git clone -q --no-hardlinks "$SRC" "$DIR"
echo "fresh-check: $(git -C "$DIR" log -1 --oneline) in $DIR"
cd "$DIR"
# CCACHE=1: compile through the developer's ccache (same objects, faster; the tests still run
# on the fresh tree). Off by default (BTFC_CCACHE=0 for scripts/build.sh and the sanitizer
# build): a fresh machine has no cache.
if [ "${CCACHE:-0}" = 1 ] && command -v ccache >/dev/null; then
  export BTFC_CCACHE=1
else
  export BTFC_CCACHE=0
fi
t0=$(date +%s)
# The README's test command (set-up, build, both passes), with other BLAS kernels.
OPENBLAS_CORETYPE=${CORETYPE:-Haswell} scripts/test.sh
t1=$(date +%s)
echo "== fresh-check: one thread (OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1), CPU path"
(cd build && OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 BTFC_FORCE_CPU=1 OPENBLAS_CORETYPE=${CORETYPE:-Haswell} \
  ctest --output-on-failure -j "$(nproc)")
t2=$(date +%s)
echo "fresh-check: passed (test.sh $((t1 - t0)) s, one-thread pass $((t2 - t1)) s)"
