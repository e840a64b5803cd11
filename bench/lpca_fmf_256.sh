#!/bin/bash
# lpca against fmf at equal bytes on a 256 x 256 texel, 81 x 81 direction synthetic BTF
# (btfc synth: 5.16 GB of float32, the full UBO2003 sampling; synth offers no direction subset
# between one direction and the full sets, so the full 81 x 81 is used). fmf:rank=73 (half) is
# the rank whose payload 170 446 x rank bytes matches lpca's default (32 clusters x 8
# components, 12.52 MB) within 1 %. Needs ~12 GB of memory (input + decoded) and, on 2 shared
# cores, the better part of an hour. Usage: BTFC=build/btfc bench/lpca_fmf_256.sh WORKDIR [SPECS...]
set -eu
W=$1; shift
B="${BTFC:-build/btfc}"
mkdir -p "$W"
[ -f "$W/s256.btfc" ] || "$B" -q synth --width 256 --height 256 -o "$W/s256.btfc"
SPECS=("$@")
[ ${#SPECS[@]} -gt 0 ] || SPECS=(lpca fmf:rank=73 lpca:precision=q:bits=6)
ARGS=()
for s in "${SPECS[@]}"; do ARGS+=(-c "$s"); done
"$B" bench "$W/s256.btfc" "${ARGS[@]}" --no-renders --throughput-queries 0 --csv "$W/s256.csv" --append
