#!/usr/bin/env bash
# ctest viewer_browser (issue 21): the web viewer (viewer/) in headless Chromium.
#  1. installs the viewer's pinned npm packages into VIEWER_DIR (viewer/install.sh);
#  2. crops the textile (DATA_DIR/textile_lurex_utia64) to its central 32 x 32 texels and
#     compresses it with every codec at its default spec (the whole 64 x 64 textile takes 160 s
#     to compress here, mlvq 100 s of it; the crop about 30 s), two codecs at a time, exports
#     each (default and 512 x 512 direction maps), and renders it with `btfc render` (flat sample
#     and sphere, fixed view and point light, reinhard tone map);
#  3. makes broken exports (a texture missing, a manifest that is not JSON, a texture cut short);
#  4. runs browser_test.mjs: the viewer's flat and sphere screenshots against the renders (and
#     against renders of another scene, which must fail), the broken exports' messages on the
#     page, two exports side by side, the light dragged, a perspective sphere drawn, the first
#     codec's sphere from its default export, and fmf's mip levels (every level on the GPU, level
#     1 the 2 x 2 average of level 0, the last the sample's average) through the LOD slider.
# Before any of that, `btfc view`'s refusals (no manifest.json, no viewer installed) are checked.
# Exit 77 (ctest: skipped, with the reason) without chromium, node or npm, or when the npm
# install fails. Usage: BTFC=... CROP=... DATA_DIR=... SOURCE_DIR=... VIEWER_DIR=... browser_test.sh WORK
set -uo pipefail
W=$1
# Once per suite run: the CPU pass (BTFC_FORCE_CPU=1) would compress the same crop on the CPU
# path and compare the same viewer again (the kernels' equivalence is tested elsewhere); skipped
# there to keep the test command's time down (about 100 s per run on 2 cores).
if [ "${BTFC_FORCE_CPU:-0}" = 1 ]; then
  echo "SKIP: the browser test runs in the suite's OpenCL pass only (BTFC_FORCE_CPU=1 here)"; exit 77
fi
rm -rf "$W" && mkdir -p "$W" || exit 1

# `btfc view` refuses what it cannot serve, before any server starts (no browser needed).
mkdir -p "$W/not_an_export"
out=$("$BTFC" view "$W/not_an_export" --port 0 2>&1); rc=$?
[ $rc -eq 1 ] && grep -q "no manifest.json: not a btfc export directory" <<<"$out" \
  || { echo "FAIL view of a directory without manifest.json: exit $rc: $out"; exit 1; }
echo "ok   view refuses a directory without manifest.json: $out"
echo '{}' > "$W/not_an_export/manifest.json"
out=$("$BTFC" view "$W/not_an_export" --port 0 --viewer "$W/nowhere" 2>&1); rc=$?
[ $rc -eq 1 ] && grep -q "web viewer was not found" <<<"$out" || { echo "FAIL view without the viewer: exit $rc: $out"; exit 1; }
echo "ok   view without the viewer installed: $out"

CHROMIUM=$(command -v chromium || command -v chromium-browser || true)
[ -n "$CHROMIUM" ] || { echo "chromium not found: viewer browser test skipped (apt-get install chromium)"; exit 77; }
command -v node >/dev/null || { echo "node not found: viewer browser test skipped (apt-get install nodejs npm)"; exit 77; }
bash "$SOURCE_DIR/viewer/install.sh" "$VIEWER_DIR"; rc=$?
[ $rc -eq 0 ] || exit $rc
out=$(timeout 2 "$BTFC" view "$W/not_an_export" --port 0 --viewer "$VIEWER_DIR" 2>&1)
grep -q "built without cpp-httplib" <<<"$out" && { echo "btfc was built without cpp-httplib: viewer browser test skipped ($out)"; exit 77; }
grep -q "btfc viewer at http://127.0.0.1:" <<<"$out" || { echo "FAIL btfc view did not print its URL: $out"; exit 1; }
echo "ok   view prints its URL: $out"
TEXTILE=$DATA_DIR/textile_lurex_utia64
[ -d "$TEXTILE" ] || { echo "FAIL test data missing: $TEXTILE"; exit 1; }
cd "$W" || exit 1

# The fixed scene: view from theta 30 phi 90, point light at theta 40 phi 30, 2 sample widths
# away; +1 EV and reinhard, so the textile's highlights (450 x the median) stay in 8 bits.
VIEW=30,90 LIGHT=40,30 DIST=2 EV=1
QUERY="view=$VIEW&light=$LIGHT&distance=$DIST&exposure=$EV&tonemap=reinhard&intensity=1"
"$CROP" "$TEXTILE" crop.btfc 16 16 32 32 || { echo "FAIL crop"; exit 1; }
echo "cropped the textile in $SECONDS s"
# Two codecs at a time (this machine's 2 cores): mlvq's 20 s then overlaps the other three.
prepare() {
  local c=$1 t0
  t0=$(date +%s.%N)
  "$BTFC" -q compress crop.btfc -c "$c" -o "$c.btfc" &&
    "$BTFC" -q export "$c.btfc" --to "$c" --no-previews --no-bsvtf &&
    "$BTFC" -q export "$c.btfc" --to "$c.map512" --no-previews --no-bsvtf --direction-map 512 &&
    "$BTFC" -q render "$c.btfc" -o "$c.render.png" --view $VIEW --light $LIGHT --distance $DIST --exposure $EV --tonemap reinhard &&
    "$BTFC" -q render "$c.btfc" -o "$c.sphere.png" --shape sphere --size 64 --view $VIEW --light $LIGHT --distance $DIST --exposure $EV --tonemap reinhard &&
    awk -v c="$c" -v t0="$t0" -v t1="$(date +%s.%N)" 'BEGIN { printf "prepared %s (compress, export, render) in %.1f s\n", c, t1 - t0 }' > "$c.ok"
}
codecs=$("$BTFC" codecs --names)
for c in $codecs; do
  prepare "$c" > "$c.log" 2>&1 &
  [ "$(jobs -rp | wc -l)" -lt 2 ] || wait -n
done
wait
# The comparisons must be able to fail: the first codec under another light, and its sphere with
# the texture repeated twice.
first=$("$BTFC" codecs --names | head -1)
cases=""
for c in $codecs; do
  [ -f "$c.ok" ] || { echo "FAIL compress / export / render $c:"; cat "$c.log"; exit 1; }
  cat "$c.ok"
  cases+="${cases:+,}{\"name\": \"$c\", \"dir\": \"$W/$c\", \"reference\": \"$W/$c.render.png\""
  [ "$c" = "$first" ] && cases+=", \"wrong\": {\"reference\": \"$W/wrong.render.png\", \"what\": \"under another light\"}"
  cases+="}"
  # The default export blends measured directions by barycentric weights sampled at the centres
  # of 64 x 64 parabolic cells, btfc render at the exact direction (docs/exports.md: 13 % of rms):
  # that is most of the difference. With 512 x 512 maps what remains is half storage and 8-bit
  # output, so the viewer itself must agree far closer (measured 49-52 dB).
  cases+=",{\"name\": \"$c --direction-map 512\", \"dir\": \"$W/$c.map512\", \"reference\": \"$W/$c.render.png\", \"min\": 45}"
  # The viewer's sphere mode against `btfc render --shape sphere` (64 x 64, the disc's pixels): its
  # grazing directions magnify the direction maps' error (default export 29.8-39.0 dB, not
  # checked), and a few pixels at the lurex's highlights differ even with 512 x 512 maps
  # (41.5-55.0 dB): the bound 40 dB still fails for a wrong texture mapping (12.8 dB, checked).
  cases+=",{\"name\": \"$c sphere --direction-map 512\", \"dir\": \"$W/$c.map512\", \"reference\": \"$W/$c.sphere.png\", \"min\": 40,"
  cases+=" \"query\": \"mode=rsphere&size=64&tiles=1\", \"mask\": \"disc\""
  [ "$c" = "$first" ] && cases+=", \"wrong\": {\"reference\": \"$W/wrong.sphere.png\", \"what\": \"with the texture repeated twice\"}"
  cases+="}"
  # The sphere from the default export (64 x 64 direction maps), for the first codec (2 s): the
  # maps' cell-centre weights, magnified at the sphere's grazing directions, cost it 6 dB against
  # the flat scene (fmf 32.7 dB; mlvq 39.0, lpyr 29.8, lpca 29.8 measured, not checked); the
  # bound 30 dB keeps that from getting worse and still fails for the doubled texture (12.8 dB).
  if [ "$c" = "$first" ]; then
    cases+=",{\"name\": \"$c sphere (default export)\", \"dir\": \"$W/$c\", \"reference\": \"$W/$c.sphere.png\", \"min\": 30,"
    cases+=" \"query\": \"mode=rsphere&size=64&tiles=1\", \"mask\": \"disc\","
    cases+=" \"wrong\": {\"reference\": \"$W/wrong.sphere.png\", \"what\": \"with the texture repeated twice\"}}"
  fi
done

"$BTFC" -q render "$first.btfc" -o wrong.render.png --view $VIEW --light 60,200 --distance $DIST --exposure $EV --tonemap reinhard || exit 1
"$BTFC" -q render "$first.btfc" -o wrong.sphere.png --shape sphere --size 64 --tiles 2 --view $VIEW --light $LIGHT --distance $DIST \
  --exposure $EV --tonemap reinhard || exit 1
# Broken exports: a texture file missing; a manifest cut in the middle; a texture cut short.
cp -r "$first" missing_texture && rm "missing_texture/$(ls "$first" | grep ktx2 | head -1)"
cp -r "$first" bad_manifest && head -c 200 "$first/manifest.json" > bad_manifest/manifest.json
missing=$(ls "$first" | grep ktx2 | head -1)
cut=$(ls "$first" | grep ktx2 | tail -1)
cp -r "$first" truncated_ktx2 && head -c 1000 "$first/$cut" > "truncated_ktx2/$cut"

cat > config.json <<JSON
{ "btfc": "$BTFC", "chromium": "$CHROMIUM", "query": "$QUERY",
  "cases": [$cases],
  "broken": [{"name": "missing texture", "dir": "$W/missing_texture", "expect": "($missing): missing"},
             {"name": "bad manifest", "dir": "$W/bad_manifest", "expect": "manifest.json is not valid JSON"},
             {"name": "truncated texture", "dir": "$W/truncated_ktx2", "expect": "$cut: truncated"}],
  "lod": [{"name": "fmf mip levels", "dir": "$W/fmf", "min": 40, "maxOff": 3,
           "query": "view=$VIEW&light=$LIGHT&distance=0&exposure=0&tonemap=none&intensity=1&mode=flat&zoom=1"}],
  "side_by_side": ["$W/fmf", "$W/lpca"],
  "shots": [{"name": "shot_sphere_fmf", "dir": "$W/fmf", "query": "$QUERY&mode=sphere&size=256"}] }
JSON
t0=$SECONDS
node "$SOURCE_DIR/tests/viewer/browser_test.mjs" "$VIEWER_DIR" "$W" config.json; rc=$?
echo "browser checks took $((SECONDS - t0)) s; the whole test $SECONDS s"
exit $rc
