#!/usr/bin/env bash
# The installed package, used from outside the source tree (issue 20):
#   1. `cmake --install` of this build into a fresh prefix: programs, libraries, headers, kernels,
#      man page, completions, CMake package, Python module;
#   2. tests/consumer (copied out of the tree) configured with find_package(btfc) against the
#      prefix only, built and run; its numbers equal the installed CLI's on the same input;
#   3. the web viewer installed under share/btfc/viewer and found there by the installed btfc view
#      (issue 21), which serves the page and three.js when they were installed into the build tree;
#   4. the installed Python module imported from the prefix in another directory, its numbers
#      equal the CLI's.
# Env: BUILD_DIR, SOURCE_DIR, CMAKE, CXX, PYTHON (empty: no Python module built, step 4 skipped
# with a message; curl fetches the viewer's files).   Usage: install_test.sh WORK_DIR
set -uo pipefail
W=$1
# Once per suite run: what is installed and how a consumer builds does not depend on the device
# path, which the suite's second pass (BTFC_FORCE_CPU=1) changes; skipped there (35 s on 2 cores).
if [ "${BTFC_FORCE_CPU:-0}" = 1 ]; then
  echo "SKIP: the install test runs in the suite's first pass only (BTFC_FORCE_CPU=1 here)"; exit 77
fi
rm -rf "$W" && mkdir -p "$W"
fails=0
# shellcheck source=tests/cli_lib.sh
source "$SOURCE_DIR/tests/cli_lib.sh"
P="$W/prefix"

check install 0 "$CMAKE" --install "$BUILD_DIR" --prefix "$P"
for f in bin/btfc share/man/man1/btfc.1 share/bash-completion/completions/btfc lib/cmake/btfc/btfcConfig.cmake \
         lib/cmake/btfc/btfcTargets.cmake lib/libbtfc_core.a lib/libbtfc_io.a include/btfc/codecs/codec.h \
         include/btfc/formats/reader.h include/btfc/core/btf.h include/btfc/kernels/btfc_shared.h share/btfc/kernels/fmf.cl \
         lib/btfc/libbtfc_imageio.so; do
  [ -s "$P/$f" ] || { echo "FAIL installed: $f"; fails=$((fails + 1)); missing=1; }
done
[ -z "${missing:-}" ] && echo "ok   installed-files"
BTFC="$P/bin/btfc"
check installed-program 0 "$BTFC" -q synth --width 12 --height 10 --seed 4 -o "$W/s.btfc"
# An image set (EXR), written by the installed program through the installed image plugin: the
# consumer reads it, so it must find the plugin of its prefix, not the build tree's.
check installed-images 0 "$BTFC" -q synth --width 12 --height 10 --seed 4 -o "$W/set"

# The consumer, outside the source tree, sees only the prefix.
cp -r "$SOURCE_DIR/tests/consumer" "$W/consumer-src"
check consumer-configure 0 "$CMAKE" -S "$W/consumer-src" -B "$W/consumer-build" -DCMAKE_BUILD_TYPE=Release \
  -DCMAKE_PREFIX_PATH="$P" -DCMAKE_CXX_COMPILER="$CXX"
check consumer-build 0 "$CMAKE" --build "$W/consumer-build"
mkdir -p "$W/c"
check consumer-run 0 "$W/consumer-build/btfc_consumer" "$W/set" fmf:rank=6 "$W/c"
cp "$W/out.txt" "$W/consumer.json"
expect_grep consumer-uses-prefix-plugin "\"imageio\": \"$P/lib/btfc/libbtfc_imageio.so\"" "$W/consumer.json"
check cli-compress 0 "$BTFC" -q compress "$W/set" -c fmf:rank=6 -o "$W/cli.btfc"
check cli-compare 0 "$BTFC" --json compare "$W/set" "$W/cli.btfc"
cp "$W/out.txt" "$W/cli-compare.json"
check same-model 0 "$BTFC" --json compare "$W/cli.btfc" "$W/c/consumer.btfc"
cp "$W/out.txt" "$W/same.json"
check cli-eval 0 "$BTFC" --json eval "$W/cli.btfc" --texel 0,0 --wl "$(awk 'BEGIN{printf "%.17g,%.17g", 0.5*180/3.141592653589793, 0.7*180/3.141592653589793}')" \
  --wv "$(awk 'BEGIN{printf "%.17g,%.17g", 0.2*180/3.141592653589793, 1.9*180/3.141592653589793}')"
cp "$W/out.txt" "$W/cli-eval.json"
[ -s "$W/c/gpu/manifest.json" ] && echo "ok   consumer-export" || { echo "FAIL consumer-export"; fails=$((fails + 1)); }
# Numbers: the consumer's PSNR and RMSE are the CLI's (same library, same spec); its model decodes
# to the CLI's (rmse 0); its region decode equals its full decode; eval agrees with `btfc eval`.
if command -v "${PYTHON:-python3}" >/dev/null; then
  "${PYTHON:-python3}" - "$W" <<'PY' && echo "ok   consumer-numbers-equal-cli" || { echo "FAIL consumer-numbers-equal-cli"; fails=$((fails + 1)); }
import json, sys
w = sys.argv[1]
c = json.load(open(f"{w}/consumer.json"))
cli = json.load(open(f"{w}/cli-compare.json"))
same = json.load(open(f"{w}/same.json"))
ev = json.load(open(f"{w}/cli-eval.json"))["value"]
ok = c["psnr"] == cli["psnr"] and c["rmse"] == cli["rmse"] and same["rmse"] == 0 and c["region_max_diff"] == 0
ok = ok and all(abs(a - b) <= 1e-5 * max(1e-6, abs(b)) for a, b in zip(c["eval"], ev))
print(c, cli["psnr"], same["rmse"], ev)
sys.exit(0 if ok else 1)
PY
fi

# The web viewer under share/btfc/viewer, found there by the installed `btfc view` (not the build
# tree's: the prefix's bin/ has no viewer/ beside it, and BTFC_VIEWER_DIR is unset). With three.js
# installed into the build tree (viewer/install.sh, run by the browser test), the installed server
# must serve the page and every module it imports; without it, btfc view must name the installed
# viewer directory and say the npm packages are missing.
V="$P/share/btfc/viewer"
for f in index.html main.js export.js manifest.js ktx2.js material.js shapes.js style.css; do
  cmp -s "$SOURCE_DIR/viewer/$f" "$V/$f" || { echo "FAIL viewer-installed: $V/$f"; fails=$((fails + 1)); vmissing=1; }
done
[ -z "${vmissing:-}" ] && echo "ok   viewer-installed"
if [ -f "$BUILD_DIR/viewer/node_modules/three/build/three.module.js" ] && ! command -v curl >/dev/null; then
  echo "SKIP viewer-served-from-prefix: curl not found (apt-get install curl)"
elif [ -f "$BUILD_DIR/viewer/node_modules/three/build/three.module.js" ]; then
  env -u BTFC_VIEWER_DIR "$BTFC" --json view "$W/c/gpu" --port 0 > "$W/view.out" 2> "$W/view.err" &
  vpid=$!
  for _ in $(seq 100); do grep -q '"url"' "$W/view.out" && break; sleep 0.1; done
  url=$(sed -n 's/.*"url":"\(http[^"?]*\)[^"]*".*/\1/p' "$W/view.out")
  served=$(sed -n 's/.*"viewer":"\([^"]*\)".*/\1/p' "$W/view.out")
  vok=1
  [ "$served" = "$V" ] || { echo "FAIL viewer-found: serves '$served', not $V: $(cat "$W/view.out" "$W/view.err")"; vok=0; }
  # The page, the modules its import map and its scripts load, and the export's manifest.
  for f in index.html main.js node_modules/three/build/three.module.js node_modules/three/build/three.core.js \
           node_modules/three/examples/jsm/controls/OrbitControls.js a/manifest.json; do
    code=$(curl -s -o "$W/fetched" -w '%{http_code}' "$url$f")
    [ "$code" = 200 ] && [ -s "$W/fetched" ] || { echo "FAIL viewer-served: $url$f: HTTP $code"; vok=0; }
  done
  cmp -s "$W/fetched" "$W/c/gpu/manifest.json" || { echo "FAIL viewer-served: a/manifest.json is not the export's"; vok=0; }
  kill "$vpid" 2>/dev/null; wait "$vpid" 2>/dev/null
  [ $vok = 1 ] && echo "ok   viewer-served-from-prefix ($served at $url)" || fails=$((fails + 1))
else
  out=$(env -u BTFC_VIEWER_DIR "$BTFC" view "$W/c/gpu" --port 0 2>&1); rc=$?
  if [ $rc -eq 1 ] && grep -qF "$V: the viewer's npm packages are not installed" <<<"$out"; then
    echo "ok   viewer-found-in-prefix (three.js not installed into the build tree, so not into the prefix: $out)"
  else
    echo "FAIL viewer-found-in-prefix: exit $rc: $out"; fails=$((fails + 1))
  fi
fi

# The Python module from the prefix, in a directory outside the source and build trees.
if [ -n "${PYTHON:-}" ]; then
  SITE=$(find "$P" -name 'btfc*.so' -path '*dist-packages*' -printf '%h\n' | head -1)
  if [ -z "$SITE" ]; then
    echo "FAIL python-installed: no btfc module under $P"; fails=$((fails + 1))
  else
    (cd "$W" && env -u PYTHONPATH PYTHONPATH="$SITE" "$PYTHON" - "$W" "$P" <<'PY') && echo "ok   python-from-prefix" || { echo "FAIL python-from-prefix"; fails=$((fails + 1)); }
import json, subprocess, sys
import btfc
w, prefix = sys.argv[1], sys.argv[2]
assert btfc.__file__.startswith(prefix), btfc.__file__
b = btfc.open(f"{w}/set")
m = btfc.compress(b, "fmf:rank=6")
r = btfc.compare(b, m.decode())
cli = json.load(open(f"{w}/cli-compare.json"))
assert r["psnr"] == cli["psnr"] and r["rmse"] == cli["rmse"], (r, cli)
print("python from", btfc.__file__, "psnr", r["psnr"])
PY
  fi
else
  echo "SKIP python-from-prefix: the Python module is not built"
fi

echo "$fails failure(s)"
[ "$fails" -eq 0 ]
