#!/usr/bin/env bash
# Regenerates tests/golden/: a tiny synthetic BTF, one model per codec made by today's code, and
# each model's decoded values (raw .btfc). Run only when a codec's payload version is bumped on
# purpose: the golden test exists so that old files keep loading and decoding to the same values.
# Usage: scripts/regen_golden.sh [path/to/btfc]
set -euo pipefail
cd "$(dirname "$0")/.."
B=${1:-build/btfc}
G=tests/golden
mkdir -p "$G"
rm -f "$G"/*.btfc
"$B" -q synth --width 6 --height 5 --views 30,90 --seed 11 -o "$G/input.btfc"
"$B" -q --device cpu compress "$G/input.btfc" -c fmf:rank=4 -o "$G/fmf.btfc"
"$B" -q --device cpu compress "$G/input.btfc" -c fmf:rank=3:color=dfmf:chroma_rank=2:precision=float -o "$G/fmf_dfmf.btfc"
"$B" -q --device cpu compress "$G/input.btfc" -c lpyr:y=4:c=1 -o "$G/lpyr.btfc"
"$B" -q --device cpu compress "$G/input.btfc" -c lpca:clusters=3:components=2:iters=3 -o "$G/lpca.btfc"
"$B" -q --device cpu compress "$G/input.btfc" -c mlvq:scheme=2:phi=8:theta=4:alpha=7:beta=7 -o "$G/mlvq.btfc"
for m in fmf fmf_dfmf lpyr lpca mlvq; do
  "$B" -q --device cpu decompress "$G/$m.btfc" -o "$G/$m.decoded.btfc"
done
ls -l "$G"
