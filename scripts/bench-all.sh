#!/usr/bin/env bash
# Runs `btfc bench` over every codec (with a sweep of each one's quality knob) on the embedded
# synthetic BTF, on the real measured slice and on the HDR textile in ../shared/data (when present),
# then draws the plots (docs/plots/) and regenerates the bench table in docs/benchmarks.md from the
# CSV, with the table "which codec wins at equal bytes" per data set and metric (RMSE, PSNR, MSSIM).
#   scripts/bench-all.sh [OUT_DIR]      (default build/bench-all; 11 minutes on 2 shared cores with the textile)
#   BTFC=/path/to/btfc scripts/bench-all.sh [OUT_DIR]   measure that binary: no setup, no build
set -euo pipefail
cd "$(dirname "$0")/.."
RUN="scripts/bench-all.sh${1:+ $1}"   # as stated in docs/benchmarks.md
if [ -z "${BTFC:-}" ]; then
  scripts/setup.sh
  scripts/build.sh >/dev/null
  BTFC=build/btfc
else
  RUN="BTFC=$BTFC $RUN"
fi
OUT=${1:-build/bench-all}
mkdir -p "$OUT"
CSV="$OUT/bench.csv"
rm -f "$CSV"
specs=(-c fmf:rank=2,4,8,16,32 -c fmf:precision=q:bits=6:rank=16,64,160 -c fmf:color=dfmf:rank=8,16,32 -c fmf:color=dfmf:precision=q:bits=6:rank=16,64,160 -c lpyr:y=2,4,8 -c lpyr:precision=q:bits=6:y=8,32 -c lpca:clusters=8:components=2,4,8
       -c lpca:precision=q:bits=6:components=4,16 -c mlvq -c mlvq:ssim1=0.95:ssim2=0.95)
SYNTH=("$BTFC" -q --force synth --width 64 --height 64 -o "$OUT/synthetic-64.btfc")
"${SYNTH[@]}"
"$BTFC" bench "$OUT/synthetic-64.btfc" --label synthetic-64 "${specs[@]}" --csv "$CSV" --append --renders "$OUT/renders" --pareto
REAL=../shared/data/ubo2003_tv000_pv000_81lights
if [ -d "$REAL" ]; then
  "$BTFC" bench "$REAL" --label ubo2003-slice "${specs[@]}" --csv "$CSV" --append --renders "$OUT/renders" --pareto
fi
# The full 81 x 81 direction HDR textile: noise, highlights, shadows, masking.
TEXTILE=../shared/data/textile_lurex_utia64
if [ -d "$TEXTILE" ]; then
  "$BTFC" bench "$TEXTILE" --label textile-hdr "${specs[@]}" --csv "$CSV" --append --renders "$OUT/renders" --pareto
fi
# Debian's interpreter: python3-matplotlib is installed for it, not for a pyenv python3 on PATH.
/usr/bin/python3 scripts/plot_bench.py docs/plots "$CSV" --doc docs/benchmarks.md --run "$RUN" --run "${SYNTH[*]}"
