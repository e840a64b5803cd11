#!/usr/bin/env bash
# The main job on an embedded default: synthesize a demo BTF, compress it with every registered
# codec, decode, compare, and print one table row per codec; export every model for the GPU;
# compress it out of core and over 2 MPI ranks; then the table on the real measured slice in
# ../shared/data when it is present.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
scripts/build.sh >/dev/null
BTFC=${BTFC_BUILD_DIR:-build}/btfc
WORK=$(mktemp -d /tmp/btfc-demo.XXXXXX)
trap 'rm -rf "$WORK"' EXIT

echo "== synthetic BTF: 64x64 texels, 81 x 81 UBO2003 directions"
"$BTFC" synth --width 64 --height 64 --seed 7 -o "$WORK/demo.btfc"
specs=()
for c in $("$BTFC" codecs --names); do specs+=(-c "$c"); done
"$BTFC" bench "$WORK/demo.btfc" --label synthetic-64 "${specs[@]}"

echo
echo "== GPU export of every codec's model (KTX2 + manifest + GLSL; fmf also model.bsvtf)"
for c in $("$BTFC" codecs --names); do
  "$BTFC" -q compress "$WORK/demo.btfc" -c "$c" -o "$WORK/demo.$c.btfc"
  "$BTFC" export "$WORK/demo.$c.btfc" --to "$WORK/export-$c" --no-previews | head -1
done

echo
echo "== out of core: the same BTF (322 MB as float32) within --max-memory 100M, then across 2 MPI ranks"
"$BTFC" compress "$WORK/demo.btfc" -c fmf:rank=32 -o "$WORK/demo.ooc.btfc" --max-memory 100M
"$BTFC" compare --no-ssim "$WORK/demo.btfc" "$WORK/demo.ooc.btfc"
MPI_BIN=${BTFC_BUILD_DIR:-build}/btfc-mpi
if [ -x "$MPI_BIN" ] && command -v mpirun >/dev/null; then
  OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 \
    mpirun --oversubscribe -n 2 "$MPI_BIN" compress "$WORK/demo.btfc" -c fmf:rank=32 -o "$WORK/demo.mpi.btfc" --max-memory 100M
  "$BTFC" compare --no-ssim "$WORK/demo.ooc.btfc" "$WORK/demo.mpi.btfc"
fi

REAL=../shared/data/ubo2003_tv000_pv000_81lights
if [ -d "$REAL" ]; then
  echo
  echo "== real measured slice: $REAL (1 view x 81 lights, 256x256)"
  "$BTFC" bench "$REAL" --label ubo2003-slice "${specs[@]}"
fi
echo
echo "ratio = float32 size / model payload; PSNR peak 1 for LDR data, the data maximum for HDR"
