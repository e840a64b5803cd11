#!/usr/bin/env bash
# Nothing is lost (cli/outputs.h), through the real binary: real runs killed with SIGINT and
# SIGTERM in the middle leave no temporaries or working files and exit 130 / 143 saying
# "interrupted"; an output that is the input is refused (also through a symlink and for a
# directory containing it); existing outputs need --force, and a failed or interrupted --force
# run keeps the old output. Usage: BTFC=path/to/btfc interrupt_test.sh WORKDIR
set -uo pipefail
set -m  # background jobs get their own process group and default SIGINT handling
W=$1
rm -rf "$W" && mkdir -p "$W"
fails=0
source "$(dirname "$0")/cli_lib.sh"  # check, expect_grep
no_leftovers() { # no_leftovers NAME DIR: nothing temporary in DIR
  local left
  left=$(ls -A "$2" | grep -E '\.tmp-|\.btfc-work-|\.btfc-old-')
  if [ -n "$left" ]; then echo "FAIL $1: left behind: $left"; fails=$((fails + 1)); else echo "ok   $1"; fi
}
# interrupt NAME SIGNAL WANT_EXIT WAIT_FOR_GLOB CMD...: starts CMD, waits until a file matching
# WAIT_FOR_GLOB (in $W/run) exists (the run is in the middle of its work), sends SIGNAL.
interrupt() {
  local name=$1 sig=$2 want=$3 glob=$4; shift 4
  "$@" >"$W/out.txt" 2>"$W/err.txt" &
  local pid=$! t=0
  until compgen -G "$W/run/$glob" >/dev/null; do
    sleep 0.01; t=$((t + 1))
    if [ $t -gt 6000 ] || ! kill -0 $pid 2>/dev/null; then break; fi
  done
  # Soon after the file appears: a whole out-of-core run of this size takes under a second on
  # one thread (0.7 s on a Zen 3 VM, most of it after the working file appears).
  sleep 0.05
  kill -s "$sig" $pid 2>/dev/null
  wait $pid
  local got=$?
  if [ "$got" -ne "$want" ]; then echo "FAIL $name: exit $got, wanted $want"; cat "$W/err.txt"; fails=$((fails + 1)); else echo "ok   $name"; fi
  expect_grep "$name-message" "interrupted" "$W/err.txt"
}

mkdir -p "$W/run"
# 64 x 64 texels x 81 x 81 x RGB = 322 MB as float32; --max-memory 48M streams it through a
# half-float working file beside the output (.btfc-work-PID.btf, 161 MB).
check synth 0 "$BTFC" synth --width 64 --height 64 --seed 2 -o "$W/big.btfc"
SPEC=fmf:rank=8:oversample=4:power_iters=4
interrupt ooc-sigint INT 130 '.btfc-work-*' "$BTFC" compress "$W/big.btfc" -c $SPEC -o "$W/run/m.btfc" --max-memory 48M
no_leftovers ooc-sigint-clean "$W/run"
[ ! -e "$W/run/m.btfc" ] && echo "ok   ooc-sigint-no-output" || { echo "FAIL ooc-sigint-no-output"; fails=$((fails + 1)); }
interrupt ooc-sigterm TERM 143 '.btfc-work-*' "$BTFC" compress "$W/big.btfc" -c $SPEC -o "$W/run/m.btfc" --max-memory 48M
no_leftovers ooc-sigterm-clean "$W/run"
# An interrupted --force run keeps the output it was to replace.
echo "old output" >"$W/run/keep.btfc"
interrupt force-sigint INT 130 '.btfc-work-*' "$BTFC" --force compress "$W/big.btfc" -c $SPEC -o "$W/run/keep.btfc" --max-memory 48M
no_leftovers force-sigint-clean "$W/run"
expect_grep force-sigint-kept "old output" "$W/run/keep.btfc"
# A decode into an image set (a temporary directory renamed at the end), killed half way.
check small 0 "$BTFC" compress "$W/big.btfc" -c fmf:rank=4 -o "$W/small.btfc"
interrupt images-sigterm TERM 143 'imgs.tmp-*' "$BTFC" decompress "$W/small.btfc" -o "$W/run/imgs"
no_leftovers images-sigterm-clean "$W/run"
[ ! -e "$W/run/imgs" ] && echo "ok   images-no-output" || { echo "FAIL images-no-output"; fails=$((fails + 1)); }

# The output is the input: refused even with --force, the input untouched.
cp "$W/small.btfc" "$W/in.btfc"
sum=$(cksum <"$W/in.btfc")
check same-file 1 "$BTFC" --force compress "$W/in.btfc" -c fmf:rank=2 -o "$W/in.btfc"
expect_grep same-file-msg "is the input" "$W/err.txt"
ln -s "$W/in.btfc" "$W/link.btfc"
check same-symlink 1 "$BTFC" compress "$W/link.btfc" -c fmf:rank=2 -o "$W/in.btfc" --force
mkdir -p "$W/d" && cp "$W/small.btfc" "$W/d/m.btfc"
check dir-contains-input 1 "$BTFC" decompress "$W/d/m.btfc" -o "$W/d" --force
expect_grep dir-contains-msg "contains the input" "$W/err.txt"
[ "$(cksum <"$W/in.btfc")" = "$sum" ] && [ -f "$W/d/m.btfc" ] && echo "ok   inputs-untouched" || { echo "FAIL inputs-untouched"; fails=$((fails + 1)); }

# One overwrite policy for files and directories.
check first 0 "$BTFC" compress "$W/small.btfc" -c fmf:rank=2 -o "$W/o.btfc"
check exists-file 1 "$BTFC" compress "$W/small.btfc" -c fmf:rank=3 -o "$W/o.btfc"
expect_grep exists-file-msg "o.btfc: file exists (--force replaces it)" "$W/err.txt"
check force-file 0 "$BTFC" compress "$W/small.btfc" -c fmf:rank=3 -o "$W/o.btfc" --force
check info-forced 0 "$BTFC" info "$W/o.btfc"
expect_grep force-file-replaced "fmf:rank=3" "$W/out.txt"
check export 0 "$BTFC" export "$W/small.btfc" --to "$W/gpu/" --no-previews --no-bsvtf
[ -f "$W/gpu/manifest.json" ] && echo "ok   export-trailing-slash" || { echo "FAIL export-trailing-slash"; ls -la "$W/gpu"; fails=$((fails + 1)); }
check exists-dir 1 "$BTFC" export "$W/small.btfc" --to "$W/gpu"
expect_grep exists-dir-msg "gpu: directory exists (--force replaces it)" "$W/err.txt"
check force-dir 0 "$BTFC" export "$W/small.btfc" --to "$W/gpu" --force --no-bsvtf
[ -d "$W/gpu/previews" ] && echo "ok   force-dir-replaced" || { echo "FAIL force-dir-replaced"; fails=$((fails + 1)); }
# A failing --force run (unknown parameter) keeps the old output.
check force-fails 1 "$BTFC" compress "$W/small.btfc" -c fmf:rnak=3 -o "$W/o.btfc" --force
check info-kept 0 "$BTFC" info "$W/o.btfc"
expect_grep force-fails-kept "fmf:rank=3" "$W/out.txt"
# Errors name the user's path, never a temporary one.
check no-dir 2 "$BTFC" compress "$W/small.btfc" -c fmf:rank=2 -o "$W/nodir/x.btfc"
expect_grep no-dir-msg "nodir/x.btfc: directory .*nodir does not exist" "$W/err.txt"
grep -q 'tmp-' "$W/err.txt" && { echo "FAIL no-dir-temp-name"; fails=$((fails + 1)); }
no_leftovers all-clean "$W"

echo "$fails failure(s)"
[ "$fails" -eq 0 ]
