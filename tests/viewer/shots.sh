#!/usr/bin/env bash
# The viewer's screenshots (docs/viewer/) and frame times (docs/benchmarks.md, "Web viewer"),
# from the exports the browser test left in its work folder (run `ctest -R viewer_browser`
# first). Not a test: it prints the milliseconds per frame of each shot (SwiftShader, this machine).
# Usage: tests/viewer/shots.sh BUILD_DIR OUT_DIR
set -euo pipefail
BUILD=$(cd "$1" && pwd) OUT=$2
SRC=$(cd "$(dirname "$0")/../.." && pwd)
W=$BUILD/tests/viewer-work
[ -d "$W/fmf" ] || { echo "no exports in $W: run ctest -R viewer_browser first"; exit 1; }
mkdir -p "$OUT"
# lpca with an environment (PRT maps), for the environment-lighting shot.
rm -rf "$W/lpca.env"
"$BUILD/btfc" -q export "$W/lpca.btfc" --to "$W/lpca.env" --env "$SRC/docs/examples/sky.exr" --no-previews
L="light=45,240&exposure=1&tonemap=reinhard"
shots=""
add() { shots+="${shots:+,}{\"name\": \"$1\", \"dir\": \"$2\", \"query\": \"$3\", \"measure\": true}"; }
for c in fmf lpyr lpca mlvq; do
  add "$c-sphere" "$W/$c" "$L&mode=sphere&size=256&repeat=2"
  add "$c-flat" "$W/$c" "$L&mode=flat&zoom=4&view=30,90&distance=2"
done
add fmf-cloth "$W/fmf" "$L&mode=cloth&size=256&repeat=2"
add lpca-environment "$W/lpca.env" "lightkind=env&exposure=-1.5&tonemap=reinhard&mode=sphere&size=256&repeat=2"
add lpyr-lod1 "$W/lpyr" "$L&mode=sphere&size=256&repeat=2&lod=1"
for c in fmf lpyr lpca mlvq; do add "$c-sphere-512" "$W/$c" "$L&mode=sphere&size=512&repeat=3"; done
cat > "$W/shots.json" <<JSON
{ "btfc": "$BUILD/btfc", "chromium": "$(command -v chromium)", "query": "", "cases": [], "broken": [], "shots": [$shots] }
JSON
node "$SRC/tests/viewer/browser_test.mjs" "$BUILD/viewer" "$W" "$W/shots.json"
for f in "$W"/*-sphere.png "$W"/*-flat.png "$W"/fmf-cloth.png "$W"/lpca-environment.png "$W"/lpyr-lod1.png; do cp "$f" "$OUT/"; done
