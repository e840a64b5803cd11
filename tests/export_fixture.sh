#!/usr/bin/env bash
# ctest fixture for the independent export checks (ktx_parse_check, glsl_validate): exports a
# synthetic BTF through the real CLI (`btfc export`) with every codec that has an exporter, and
# writes next to each export the sidecar of btfc_ktx_sidecar (what the files must contain).
# Codecs without an exporter yet are skipped (exit message "has no GPU exporter").
# Usage: BTFC=path/to/btfc SIDECAR=path/to/btfc_ktx_sidecar export_fixture.sh WORKDIR
set -euo pipefail
W=$1
rm -rf "$W" && mkdir -p "$W"
"$BTFC" -q synth --width 16 --height 12 --seed 5 -o "$W/s.btfc"
"$BTFC" -q synth --width 8 --height 6 --seed 6 --scale 1e6 -o "$W/hdr.btfc"

export_one() { # NAME SOURCE SPEC [export options]
  local name=$1 src=$2 spec=$3
  shift 3
  "$BTFC" -q compress "$W/$src.btfc" -c "$spec" -o "$W/$name.btfc"
  if ! "$BTFC" -q export "$W/$name.btfc" --to "$W/$name" "$@" 2>"$W/$name.err"; then
    if grep -q "has no GPU exporter" "$W/$name.err"; then
      echo "skip $name ($spec): no GPU exporter yet"
      return 0
    fi
    echo "FAIL $name ($spec): btfc export failed:"
    cat "$W/$name.err"
    exit 1
  fi
  "$SIDECAR" "$W/$name.btfc" "$W/$name/sidecar.json" "$@"
  echo "ok   $name ($spec $*): $(ls "$W/$name" | tr '\n' ' ')"
}

export_one fmf s fmf:rank=6
export_one fmf_dfmf s fmf:color=dfmf:rank=6:chroma_rank=3:offset=1e-5 --direction-map 16
export_one fmf_float s fmf:rank=6 --float
export_one fmf_hdr hdr fmf:rank=4:precision=float
export_one lpyr s lpyr:y=4:c=1
export_one lpca s lpca:clusters=4:components=3:iters=3
export_one mlvq s mlvq:phi=8:theta=4:alpha=7:beta=7
