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
set -euo pipefail
cd "$(dirname "$0")/.."
SRC=$(pwd)
PARENT=$(dirname "$SRC")
[ -d "$PARENT/shared" ] || echo "fresh-check: no $PARENT/shared: data-dependent tests will skip" >&2
DIR=$(mktemp -d "$PARENT/btfc-fresh-XXXXXX")
cleanup() { [ "${KEEP:-0}" = 1 ] && echo "fresh-check: kept $DIR" || rm -rf "$DIR"; }
trap cleanup EXIT
git clone -q --no-hardlinks "$SRC" "$DIR/btfc"
echo "fresh-check: $(git -C "$DIR/btfc" log -1 --oneline) in $DIR/btfc"
cd "$DIR/btfc"
t0=$(date +%s)
# The README's test command (set-up, build, both passes), with other BLAS kernels.
OPENBLAS_CORETYPE=${CORETYPE:-Haswell} scripts/test.sh
t1=$(date +%s)
echo "== fresh-check: one thread (OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1), CPU path"
(cd build && OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 BTFC_FORCE_CPU=1 OPENBLAS_CORETYPE=${CORETYPE:-Haswell} \
  ctest --output-on-failure -j "$(nproc)")
t2=$(date +%s)
echo "fresh-check: passed (test.sh $((t1 - t0)) s, one-thread pass $((t2 - t1)) s)"
