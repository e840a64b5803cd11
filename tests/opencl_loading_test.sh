#!/usr/bin/env bash
# OpenCL is loaded lazily and is optional (core/cl_api.h): btfc has no link-time OpenCL
# dependency, a bare process or a CPU-only job never loads it (nor a driver), a missing library
# means the CPU path with one warning, and --device cl then fails with a clear error.
# Usage: BTFC=path/to/btfc opencl_loading_test.sh WORKDIR
set -uo pipefail
W=$1
rm -rf "$W" && mkdir -p "$W"
fails=0
source "$(dirname "$0")/cli_lib.sh"  # check, expect_grep
# This test sets the device choice itself: the suite's CPU pass must not decide it.
unset BTFC_FORCE_CPU

# ld.so's own log (LD_DEBUG=files) of what a process loads. A job that reads an image set maps the
# ICD loader anyway on Debian, as a dependency of OpenImageIO's FFmpeg (libavutil; OpenImageIO is
# loaded on first use, formats/image_file.h), so the checks are on what btfc itself does: its
# dlopen() of libOpenCL ("opening file=...libOpenCL") and an OpenCL driver loaded by the ICD
# loader ("dynamically loaded by ...libOpenCL", PoCL and LLVM here).
# Plain greps on the files: `cat | grep -q` fails under pipefail when grep stops early.
k_btfc_dlopen='opening file=[^ ]*libOpenCL|file=libOpenCL[^ ]* \[0\];  dynamically loaded by'
k_driver='dynamically loaded by [^ ]*libOpenCL'
ld_log() {
  rm -f "$W"/ld.*
  LD_DEBUG=files LD_DEBUG_OUTPUT="$W/ld" "$@" >/dev/null 2>&1
}
# no_opencl_loaded NAME CMD...: counts a failure when CMD loads OpenCL itself or a driver.
no_opencl_loaded() {
  local name=$1; shift
  ld_log "$@"
  if grep -qE "$k_btfc_dlopen|$k_driver" "$W"/ld.*; then
    echo "FAIL $name: OpenCL was loaded:"; grep -hE "$k_btfc_dlopen|$k_driver" "$W"/ld.*; fails=$((fails + 1))
  else
    echo "ok   $name"
  fi
  rm -f "$W"/ld.*
}

needed=$(readelf -d "$BTFC" | grep NEEDED)
devices=$("$BTFC" devices 2>&1)
if grep -qi opencl <<<"$needed"; then
  echo "FAIL no-link-dependency: $(grep -i opencl <<<"$needed")"; fails=$((fails + 1))
else
  echo "ok   no-link-dependency"
fi
check synth 0 "$BTFC" synth --width 8 --height 6 --seed 2 -o "$W/s.btfc"
no_opencl_loaded bare-process "$BTFC" codecs
no_opencl_loaded device-cpu "$BTFC" --device cpu compress "$W/s.btfc" -c lpca:clusters=2:components=2 -o "$W/cpu.btfc"
no_opencl_loaded force-cpu env BTFC_FORCE_CPU=1 "$BTFC" compress "$W/s.btfc" -c lpca:clusters=2:components=2 -o "$W/force.btfc"

# Where a device works, the same job under auto does load it: lazily, but it is used.
if grep -q '^0: ' <<<"$devices"; then
  ld_log "$BTFC" compress "$W/s.btfc" -c lpca:clusters=2:components=2 -o "$W/dev.btfc"
  # Under AddressSanitizer (scripts/test-sanitize.sh) its dlopen interceptor makes every library
  # look loaded by the executable: there the driver is any library btfc loads besides libOpenCL.
  driver=$k_driver
  [ "${BTFC_SANITIZER:-0}" = 1 ] && driver='file=[^ ]*(pocl|icd|cl)[^ ]* \[0\];  dynamically loaded by [^ ]*/btfc '
  if grep -qE "$k_btfc_dlopen" "$W"/ld.* && grep -E "$driver" "$W"/ld.* | grep -vq 'file=[^ ]*libOpenCL'; then
    echo "ok   device-auto-loads"
  else
    echo "FAIL device-auto-loads: no dlopen of libOpenCL or no driver in the ld.so log"; fails=$((fails + 1))
  fi
  rm -f "$W"/ld.*
else
  echo "skip device-auto-loads: no OpenCL device here"
fi

# No loadable OpenCL library: auto runs the C++ path and says so once; cl is an error. In a
# build without OpenCL (BTFC_OPENCL=OFF) the same holds with that as the reason.
export BTFC_OPENCL_LIBRARY=/nonexistent/libOpenCL.so.1
why="cannot load the OpenCL library /nonexistent/libOpenCL.so.1"
grep -q "built without OpenCL" <<<"$devices" && why="built without OpenCL"
check missing-auto 0 "$BTFC" compress "$W/s.btfc" -c lpca:clusters=2:components=2 -o "$W/auto.btfc"
expect_grep missing-auto-warning "warning: OpenCL unavailable, running the CPU path: $why" "$W/err.txt"
n=$(grep -c "warning: OpenCL" "$W/err.txt")
[ "$n" -eq 1 ] && echo "ok   missing-auto-warned-once" || { echo "FAIL missing-auto-warned-once: $n warnings"; fails=$((fails + 1)); }
check missing-cl 3 "$BTFC" --device cl compress "$W/s.btfc" -c lpca:clusters=2:components=2 -o "$W/cl.btfc"
expect_grep missing-cl-error "error: .*OpenCL required (--device cl) but unavailable: $why" "$W/err.txt"
[ ! -e "$W/cl.btfc" ] && echo "ok   missing-cl-no-output" || { echo "FAIL missing-cl-no-output"; fails=$((fails + 1)); }
check missing-devices 0 "$BTFC" devices
expect_grep missing-devices-note "no OpenCL device: $why" "$W/out.txt"
# The CPU path's model is the same whether chosen or fallen back to.
check missing-same-model 0 "$BTFC" --json compare "$W/cpu.btfc" "$W/auto.btfc"
expect_grep missing-same-model-zero '"rmse": 0' "$W/out.txt"
unset BTFC_OPENCL_LIBRARY

echo "$fails failure(s)"
[ "$fails" -eq 0 ]
