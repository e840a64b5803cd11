#!/usr/bin/env bash
# Makes DEST (default: build/viewer) a servable copy of the viewer: the pinned npm packages
# (package-lock.json: three, and puppeteer-core for the browser test) installed by `npm ci`, and
# the viewer's own files linked in (symlinks: an edit in viewer/ shows on the next reload).
# node_modules never goes into the repository; `btfc view` looks for DEST beside its binary.
# Exit 77 (ctest: skipped) with the reason when npm is missing or the install fails.
# Usage: viewer/install.sh [DEST]
set -uo pipefail
HERE=$(cd "$(dirname "$0")" && pwd)
DEST=${1:-$HERE/../build/viewer}
mkdir -p "$DEST" || exit 1
DEST=$(cd "$DEST" && pwd)
# Reinstall only when the lock file changed (npm ci wipes node_modules: slow on 2 cores).
if ! cmp -s "$HERE/package-lock.json" "$DEST/package-lock.json" || [ ! -f "$DEST/node_modules/three/package.json" ]; then
  command -v npm >/dev/null || { echo "npm not found: cannot install the viewer's packages (apt-get install npm)"; exit 77; }
  cp "$HERE/package.json" "$HERE/package-lock.json" "$DEST/" || exit 1
  echo "installing the viewer's npm packages (three, puppeteer-core) into $DEST"
  # PUPPETEER_SKIP_DOWNLOAD: puppeteer-core downloads no browser anyway; Debian's chromium is used.
  if ! (cd "$DEST" && PUPPETEER_SKIP_DOWNLOAD=1 npm ci --no-audit --no-fund --loglevel=error); then
    rm -f "$DEST/package-lock.json"  # so the next run tries again
    echo "npm ci failed (no registry access?): viewer packages not installed"
    exit 77
  fi
fi
for f in "$HERE"/*.html "$HERE"/*.js "$HERE"/*.css; do
  [ -e "$f" ] && ln -sfn "$f" "$DEST/$(basename "$f")"
done
exit 0
