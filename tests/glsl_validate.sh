#!/usr/bin/env bash
# ctest glsl_validate: glslangValidator (Khronos' reference GLSL front end, a second compiler
# besides Mesa's) on every exported btf.frag of export_fixture.sh, as shipped (with its main)
# and as the GL harness uses it (BTFC_NO_MAIN defined, functions only: linking is skipped).
# Usage: GLSLANG=path/to/glslangValidator glsl_validate.sh WORKDIR
set -uo pipefail
W=$1
n=0 fails=0
for f in "$W"/*/btf.frag; do
  [ -f "$f" ] || continue
  n=$((n + 1))
  if out=$("$GLSLANG" -S frag "$f" 2>&1); then echo "ok   $f"; else echo "FAIL $f:"; echo "$out"; fails=$((fails + 1)); fi
  nomain=$(mktemp --suffix=.frag)
  { head -n 1 "$f"; echo "#define BTFC_NO_MAIN"; tail -n +2 "$f"; } >"$nomain"
  # Compile only (no -l: linking would demand a main).
  if out=$("$GLSLANG" -S frag "$nomain" 2>&1); then echo "ok   $f (BTFC_NO_MAIN)"; else echo "FAIL $f (BTFC_NO_MAIN):"; echo "$out"; fails=$((fails + 1)); fi
  rm -f "$nomain"
done
[ "$n" -gt 0 ] || { echo "FAIL no btf.frag under $W"; exit 1; }
echo "$n shaders, $fails failure(s)"
[ "$fails" -eq 0 ]
