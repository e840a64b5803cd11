#!/bin/bash
# A Bonn DFMF (!DFMF08FCR, colour model 11) written by btfc decodes in an independent reader that
# follows Bonn's BTFLIB (tests/bonn_dfmf_reader.py) to btfc's own values within 1e-3 relative:
# on the HDR textile (highlights 450x the median) and a synthetic HDR BTF of another size.
# Usage: BTFC=path/to/btfc PYTHON=python3-with-numpy DATA_DIR=... bonn_dfmf_interop.sh WORKDIR
set -u
W=$1
rm -rf "$W"  # a fresh folder: btfc refuses to overwrite without --force
mkdir -p "$W"
here=$(dirname "$0")
fails=0
check() {  # name input spec
  local name=$1 in=$2 spec=$3
  if ! "$BTFC" compress "$in" -c "$spec" -o "$W/$name.btf" > "$W/$name.log" 2>&1; then
    echo "FAIL $name: compress"; cat "$W/$name.log"; fails=$((fails + 1)); return
  fi
  # btfc's own decode of the file it wrote
  "$BTFC" decompress "$W/$name.btf" -o "$W/$name.dec.btfc" > /dev/null 2>&1 || { echo "FAIL $name: decompress"; fails=$((fails + 1)); return; }
  echo "-- $name: reader vs btfc's decode of the .btf"
  "$PYTHON" "$here/bonn_dfmf_reader.py" "$W/$name.btf" "$W/$name.dec.btfc" || fails=$((fails + 1))
}
check textile "$DATA_DIR/textile_lurex_utia64" fmf:color=dfmf:rank=12:chroma_rank=3:offset=1e-5
"$BTFC" synth -o "$W/s.btfc" --width 24 --height 20 --scale 500 --seed 3 > /dev/null 2>&1 || { echo "FAIL synth"; exit 1; }
check synth "$W/s.btfc" fmf:color=dfmf:rank=10:chroma_rank=4:offset=1e-5
# Writing a .btf with the offset unset takes Bonn's (and says so); an explicit other offset is
# refused with a clear error, not written wrongly.
if "$BTFC" compress "$W/s.btfc" -c fmf:color=dfmf:rank=4 -o "$W/auto.btf" > "$W/auto.log" 2>&1 && grep -q "offset=1e-5" "$W/auto.log"; then
  echo "ok   unset offset written as Bonn's 1e-5, with a note"
else
  echo "FAIL unset-offset .btf"; cat "$W/auto.log"; fails=$((fails + 1))
fi
if "$BTFC" compress "$W/s.btfc" -c fmf:color=dfmf:rank=4:offset=2 -o "$W/other.btf" > "$W/other.log" 2>&1; then
  echo "FAIL other-offset: a dfmf model with offset != 1e-5 was written as Bonn DFMF"; fails=$((fails + 1))
elif ! grep -q "offset=1e-5" "$W/other.log" || [ -e "$W/other.btf" ]; then
  echo "FAIL other-offset: unclear error or partial output"; cat "$W/other.log"; fails=$((fails + 1))
else
  echo "ok   offset=2 model refused for Bonn DFMF"
fi
[ $fails -eq 0 ] && echo "all ok" || echo "$fails failed"
exit $fails
