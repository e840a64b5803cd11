#!/usr/bin/env bash
# Regenerates tests/golden/: a tiny synthetic BTF, one model per registered codec made by today's
# code (`btfc codecs --names`: a new codec gets its file without editing this script), the
# variants whose stored layout differs from a codec's default, and each model's decoded values
# (raw .btfc). Run only when a codec's payload version is bumped on purpose, or for a new codec:
# the golden test (tests/golden_test.cpp) exists so that old files keep loading and decoding to
# the same values, and it fails for a library codec without a golden file.
# Usage: scripts/regen_golden.sh [path/to/btfc]
set -euo pipefail
cd "$(dirname "$0")/.."
B=${1:-build/btfc}
G=tests/golden
mkdir -p "$G"
rm -f "$G"/*.btfc
"$B" -q synth --width 6 --height 5 --views 30,90 --seed 11 -o "$G/input.btfc"
# Small settings of the codecs whose defaults are slow or large on 30 texels; any other codec
# is encoded at its default spec.
declare -A SPEC=(
  [fmf]="fmf:rank=4"
  [lpyr]="lpyr:y=4:c=1"
  [lpca]="lpca:clusters=3:components=2:iters=3"
  [mlvq]="mlvq:scheme=2:phi=8:theta=4:alpha=7:beta=7"
)
# Stored layouts besides the defaults: NAME=SPEC.
EXTRA=("fmf_dfmf=fmf:rank=3:color=dfmf:chroma_rank=2:precision=float")
models=()
for c in $("$B" codecs --names); do
  "$B" -q --device cpu compress "$G/input.btfc" -c "${SPEC[$c]:-$c}" -o "$G/$c.btfc"
  models+=("$c")
done
for e in "${EXTRA[@]}"; do
  "$B" -q --device cpu compress "$G/input.btfc" -c "${e#*=}" -o "$G/${e%%=*}.btfc"
  models+=("${e%%=*}")
done
for m in "${models[@]}"; do
  "$B" -q --device cpu decompress "$G/$m.btfc" -o "$G/$m.decoded.btfc"
done
ls -l "$G"
