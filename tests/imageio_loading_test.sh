#!/usr/bin/env bash
# OpenImageIO is loaded only by a process that reads or writes an image file (formats/image_file.h):
# btfc has no link-time OpenImageIO dependency, a bare process or a job on .btfc files never maps
# it, an image-set job loads btfc's plugin (libbtfc_imageio.so) and through it OpenImageIO, and a
# plugin that cannot be loaded is one clear error naming what was tried.
# Usage: BTFC=path/to/btfc imageio_loading_test.sh WORKDIR
set -uo pipefail
W=$1
rm -rf "$W" && mkdir -p "$W"
fails=0
source "$(dirname "$0")/cli_lib.sh"  # check, expect_grep

# ld.so's own log of the shared objects a process loads (LD_DEBUG=files).
ld_log() {
  rm -f "$W"/ld.*
  LD_DEBUG=files LD_DEBUG_OUTPUT="$W/ld" "$@" >/dev/null 2>&1
}
loads() { grep -qE "file=[^ ]*$1" "$W"/ld.*; }

if readelf -d "$BTFC" | grep NEEDED | grep -qi OpenImageIO; then
  echo "FAIL no-link-dependency: $(readelf -d "$BTFC" | grep NEEDED | grep -i OpenImageIO)"; fails=$((fails + 1))
else
  echo "ok   no-link-dependency"
fi
check synth 0 "$BTFC" synth --width 8 --height 6 --seed 2 -o "$W/s.btfc"
for job in "codecs" "info $W/s.btfc" "compress $W/s.btfc -c fmf:rank=2 -o $W/m.btfc"; do
  # shellcheck disable=SC2086
  ld_log "$BTFC" $job
  name="no-imageio: btfc ${job%% *}"
  if loads 'libOpenImageIO' || loads 'libbtfc_imageio'; then
    echo "FAIL $name: OpenImageIO was loaded"; fails=$((fails + 1))
  else
    echo "ok   $name"
  fi
done
# An image set written and read: the plugin and OpenImageIO are loaded, lazily, and work.
ld_log "$BTFC" synth --width 8 --height 6 --seed 2 -o "$W/imgs"
loads 'libbtfc_imageio\.so' && loads 'libOpenImageIO' && echo "ok   image-job-loads-plugin" ||
  { echo "FAIL image-job-loads-plugin: no libbtfc_imageio / libOpenImageIO in the ld.so log"; fails=$((fails + 1)); }
check read-images 0 "$BTFC" --json compare "$W/s.btfc" "$W/imgs"
expect_grep read-images-close '"psnr"' "$W/out.txt"
# A plugin that cannot be loaded: an error that names it, no output left behind.
check missing-plugin 2 env BTFC_IMAGEIO_PLUGIN=/nonexistent/libbtfc_imageio.so "$BTFC" info "$W/imgs"
expect_grep missing-plugin-message "BTFC_IMAGEIO_PLUGIN=/nonexistent/libbtfc_imageio.so cannot be loaded" "$W/err.txt"
check missing-plugin-write 2 env BTFC_IMAGEIO_PLUGIN=/nonexistent/libbtfc_imageio.so "$BTFC" synth --width 8 --height 6 -o "$W/imgs2"
[ ! -e "$W/imgs2" ] && echo "ok   missing-plugin-no-output" || { echo "FAIL missing-plugin-no-output"; fails=$((fails + 1)); }

echo "$fails failure(s)"
[ "$fails" -eq 0 ]
