#!/bin/bash
# fmf color=dfmf vs rgb fmf at (about) equal payload bytes on HDR BTFs: relative L2 and PSNR by
# `btfc compare` (--no-ssim). Per component, dfmf stores (images + texels) halves, rgb
# (3 images + texels): the rank pairs below match bytes within 5 %.
# Usage: BTFC=build/btfc bench/dfmf_hdr_bench.sh WORKDIR [DATA_DIR]
set -u
W=$1; D=${2:-$(dirname "$0")/../../shared/data}
mkdir -p "$W"
B="${BTFC:-build/btfc} --device cpu"
run() {  # input label spec
  $B compress "$1" -c "$3" -o "$W/m.btfc" > /dev/null 2>&1 || { echo "| $2 | $3 | compress failed |"; return; }
  $B decompress "$W/m.btfc" -o "$W/d.btfc" > /dev/null 2>&1
  local bytes; bytes=$($B info "$W/m.btfc" 2>/dev/null | grep -i -m1 "payload" | grep -o "[0-9]\+ bytes\|[0-9]\+$" | head -1)
  echo "| $2 | \`$3\` | $(stat -c %s "$W/m.btfc") | $($B compare "$1" "$W/d.btfc" --no-ssim | tail -1) |"
}
T=$D/textile_lurex_utia64
$B synth -o "$W/s40.btfc" --width 40 --height 40 --scale 1000 --seed 7 > /dev/null 2>&1
echo "| data | spec | file bytes | btfc compare |"
echo "|---|---|---|---|"
for pair in "8 2 5" "32 8 21"; do set -- $pair
  run "$T" textile "fmf:color=dfmf:rank=$1:chroma_rank=$2"; run "$T" textile "fmf:rank=$3"
done
run "$W/s40.btfc" "synth 40x40 x1000" "fmf:color=dfmf:rank=16:chroma_rank=4:offset=1e-5"
run "$W/s40.btfc" "synth 40x40 x1000" "fmf:color=dfmf:rank=16:chroma_rank=4"
run "$W/s40.btfc" "synth 40x40 x1000" "fmf:rank=11"
