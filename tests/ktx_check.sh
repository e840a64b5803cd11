#!/usr/bin/env bash
# ctest ktx_parse_check: installs npm's ktx-parse into the build tree once (NODE_PREFIX, e.g.
# build/node) and runs tests/ktx_parse_check.mjs over the exports of export_fixture.sh.
# Exit 77 (ctest: skipped, with the reason) when node / npm are missing or the install fails.
# Usage: ktx_check.sh NODE_PREFIX WORKDIR
set -uo pipefail
PREFIX=$1 WORK=$2
HERE=$(cd "$(dirname "$0")" && pwd)
command -v node >/dev/null || { echo "node not found: KTX2 check by ktx-parse skipped (apt-get install nodejs npm)"; exit 77; }
if [ ! -f "$PREFIX/node_modules/ktx-parse/package.json" ]; then
  command -v npm >/dev/null || { echo "npm not found: cannot install ktx-parse; skipped"; exit 77; }
  echo "installing ktx-parse@2 into $PREFIX"
  if ! npm install --prefix "$PREFIX" --no-audit --no-fund --loglevel=error ktx-parse@2; then
    echo "npm install ktx-parse@2 failed (no registry access?): skipped"
    exit 77
  fi
fi
node "$HERE/ktx_parse_check.mjs" "$PREFIX" "$WORK" || exit 1

# The checker must be able to fail: a copy of the fmf export with one level-0 byte flipped and
# one with a wrong DFD bytesPlane0 must both be rejected, naming the problem.
NEG=$(mktemp -d)
trap 'rm -rf "$NEG"' EXIT
mkdir -p "$NEG/data" "$NEG/dfd"
cp -r "$WORK/fmf" "$NEG/data/fmf" && cp -r "$WORK/fmf" "$NEG/dfd/fmf"
node -e '
const fs = require("fs");
const [data, dfd] = process.argv.slice(1);
let b = fs.readFileSync(data); b[b.length - 1] ^= 0x40; fs.writeFileSync(data, b);   // level 0 is last in the file
b = fs.readFileSync(dfd); b[b.readUInt32LE(48) + 20] += 1; fs.writeFileSync(dfd, b);  // DFD bytesPlane0
' "$NEG/data/fmf/eigen_texture.ktx2" "$NEG/dfd/fmf/eigen_abrdf.ktx2"
for t in "data:FNV-1a of the bytes" "dfd:DFD bytesPlane"; do
  if out=$(node "$HERE/ktx_parse_check.mjs" "$PREFIX" "$NEG/${t%%:*}" 2>&1); then
    echo "FAIL the checker accepted a corrupted file ($t)"; exit 1
  fi
  grep -q "${t#*:}" <<<"$out" || { echo "FAIL corrupted file ($t) rejected for another reason:"; echo "$out"; exit 1; }
  echo "ok   corrupted copy rejected: $(grep -m1 FAIL <<<"$out")"
done
