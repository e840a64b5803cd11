#!/usr/bin/env bash
# Conventions of git-style tools, through the real binary: global options before or after the
# command and listed in every command's help, --version, `btfc help CMD`, unknown commands
# named, defaults in --help, "-" as stdout only for streams, output extensions checked against
# what is written, man page and completions generated and installed.
# Usage: BTFC=path/to/btfc BUILD_DIR=... SOURCE_DIR=... conventions_test.sh WORKDIR
set -uo pipefail
W=$1
BTFC=$(realpath "$BTFC")
rm -rf "$W" && mkdir -p "$W"
fails=0
source "$(dirname "$0")/cli_lib.sh"  # check, expect_grep

check synth 0 "$BTFC" synth --width 8 --height 8 -o "$W/s.btfc" -q
check compress-q-after 0 "$BTFC" compress "$W/s.btfc" -c fmf:rank=4 -o "$W/m.btfc" -q
[ ! -s "$W/out.txt" ] && echo "ok   quiet-after" || { echo "FAIL quiet-after"; cat "$W/out.txt"; fails=$((fails + 1)); }
check info-json-after 0 "$BTFC" info "$W/m.btfc" --json
python3 -c "import json,sys; assert json.load(open(sys.argv[1]))['codec']=='fmf'; print('ok   info-json-parses')" "$W/out.txt" || fails=$((fails + 1))
check device-after 0 "$BTFC" decompress "$W/m.btfc" -o "$W/d.btfc" --device cpu
check device-before 0 "$BTFC" --device cpu --force decompress "$W/m.btfc" -o "$W/d.btfc"
check version 0 "$BTFC" --version
expect_grep version-text "^btfc [0-9]" "$W/out.txt"
check unknown-command 1 "$BTFC" foo
expect_grep unknown-command-msg "unknown command 'foo'" "$W/err.txt"
check help-cmd 0 "$BTFC" help compress
expect_grep help-cmd-text "target-psnr" "$W/out.txt"
check help-unknown 1 "$BTFC" help nope
# Every command's help lists the global options; defaults are shown.
for c in $("$BTFC" --help | awk '/^Subcommands:/ {on = 1; next} on && NF {print $1}'); do
  "$BTFC" "$c" --help >"$W/h.txt" 2>&1 || true
  for o in --json --quiet --force --device; do
    grep -q -- "$o" "$W/h.txt" || { echo "FAIL global-in-help: $c --help lacks $o"; fails=$((fails + 1)); }
  done
done
echo "ok   global-in-help (checked every command)"
"$BTFC" compress --help >"$W/h.txt"
expect_grep default-shown "seed UINT=1" "$W/h.txt"
"$BTFC" export --help >"$W/h.txt"
expect_grep default-shown-export "direction-map INT.*=64" "$W/h.txt"
# "-": stdout for streams, refused elsewhere (before any work).
(cd "$W" && "$BTFC" synth -o - >out.txt 2>err.txt); rc=$?
[ $rc -eq 1 ] && [ ! -e "$W/-" ] && echo "ok   synth-dash-refused" || { echo "FAIL synth-dash-refused: exit $rc"; ls "$W"; fails=$((fails + 1)); }
check bench-csv-stdout 0 "$BTFC" bench "$W/s.btfc" -c fmf:rank=2 --csv - --no-renders --throughput-queries 0
python3 -c "import csv,sys; r=list(csv.DictReader(open(sys.argv[1]))); assert r[0]['spec_given']=='fmf:rank=2', r; print('ok   bench-csv-parses')" "$W/out.txt" || fails=$((fails + 1))
check bench-json-stdout 0 "$BTFC" bench "$W/s.btfc" -c fmf:rank=2 --json-out - --no-renders --throughput-queries 0
python3 -c "import json,sys; j=json.load(open(sys.argv[1])); assert len(j['runs'])==1; print('ok   bench-json-parses')" "$W/out.txt" || fails=$((fails + 1))
# bench: aligned with a long label, no "nan" for the skipped rendered SSIM, columns explained.
check bench-long-label 0 "$BTFC" bench "$W/s.btfc" -c fmf:rank=2 --label a-rather-long-data-label-of-forty-chars --no-renders --throughput-queries 0
head -2 "$W/out.txt" | awk '{print length($0)}' | sort -u | wc -l | grep -q '^1$' && echo "ok   bench-aligned" || { echo "FAIL bench-aligned"; cat "$W/out.txt"; fails=$((fails + 1)); }
grep -q nan "$W/out.txt" && { echo "FAIL bench-no-nan"; fails=$((fails + 1)); } || echo "ok   bench-no-nan"
"$BTFC" bench --help >"$W/h.txt"
expect_grep bench-columns-explained "bpv = payload bits per" "$W/h.txt"
# Output extensions match what is written.
check compress-png 1 "$BTFC" compress "$W/s.btfc" -c fmf -o "$W/x.png"
[ ! -e "$W/x.png" ] && echo "ok   compress-png-nothing" || { echo "FAIL compress-png-nothing"; fails=$((fails + 1)); }
check render-btfc 1 "$BTFC" render "$W/m.btfc" -o "$W/r.btfc"
check lpca 0 "$BTFC" compress "$W/s.btfc" -c lpca:clusters=2:components=2 -o "$W/c.btfc"
check relight-png 0 "$BTFC" relight "$W/c.btfc" --env "$SOURCE_DIR/docs/examples/sky.exr" --view 30,45 -o "$W/r.png"
head -c 8 "$W/r.png" | od -c | grep -q 'P   N   G' && echo "ok   relight-png-is-png" || { echo "FAIL relight-png-is-png"; fails=$((fails + 1)); }
check relight-jpg 1 "$BTFC" relight "$W/c.btfc" --env "$SOURCE_DIR/docs/examples/sky.exr" --view 30,45 -o "$W/r.jpg"
# Any codec relights (Model::relight: quadrature over the measured lights; lpca by its PRT).
check relight-fmf 0 "$BTFC" relight "$W/m.btfc" --env "$SOURCE_DIR/docs/examples/sky.exr" --view 30,45 -o "$W/rf.exr"
[ -s "$W/rf.exr" ] && echo "ok   relight-fmf-written" || { echo "FAIL relight-fmf-written"; fails=$((fails + 1)); }
# A parameter the data cannot honour is said on stderr and stored as used (8 x 8 = 64 texels).
check clamp-rank 0 "$BTFC" compress "$W/s.btfc" -c fmf:rank=1000 -o "$W/k.btfc"
expect_grep clamp-rank-note "note: .*rank 1000 clamped to" "$W/err.txt"
check clamp-rank-info 0 "$BTFC" info "$W/k.btfc" --json
python3 -c "import json,sys; s=json.load(open(sys.argv[1]))['spec']; import re; r=int(re.search(r'rank=(\d+)', s).group(1)); assert 1 <= r <= 64, s; print('ok   clamp-rank-stored')" "$W/out.txt" || fails=$((fails + 1))
check clamp-quiet 0 "$BTFC" compress "$W/s.btfc" -c fmf:rank=1000 -o "$W/k2.btfc" -q
[ ! -s "$W/err.txt" ] && echo "ok   clamp-quiet-silent" || { echo "FAIL clamp-quiet-silent"; cat "$W/err.txt"; fails=$((fails + 1)); }
check clamp-levels 0 "$BTFC" compress "$W/s.btfc" -c lpyr:levels=9 -o "$W/ly.btfc"
expect_grep clamp-levels-note "note: .*levels asked" "$W/err.txt"
# Man page and completions: generated by the build, valid, installed by the install rules.
check man 0 "$BTFC" man
expect_grep man-th "^\.TH BTFC 1" "$W/out.txt"
expect_grep man-cmd 'SS "btfc compress"' "$W/out.txt"
"$BTFC" completion bash >"$W/btfc.bash" && bash -n "$W/btfc.bash" && echo "ok   bash-completion-syntax" || { echo "FAIL bash-completion-syntax"; fails=$((fails + 1)); }
# shellcheck disable=SC1090
out=$(source "$W/btfc.bash"; COMP_WORDS=(btfc comp); COMP_CWORD=1; _btfc; echo "${COMPREPLY[*]}")
[ "$out" = "compress compare completion" ] || [ "$out" = "compare completion compress" ] || [[ "$out" == *compress* ]] && echo "ok   bash-completion-commands" || { echo "FAIL bash-completion-commands: '$out'"; fails=$((fails + 1)); }
out=$(source "$W/btfc.bash"; COMP_WORDS=(btfc compress x --tar); COMP_CWORD=3; _btfc; echo "${COMPREPLY[*]}")
[[ "$out" == *--target-psnr* ]] && echo "ok   bash-completion-options" || { echo "FAIL bash-completion-options: '$out'"; fails=$((fails + 1)); }
if command -v zsh >/dev/null; then
  "$BTFC" completion zsh >"$W/_btfc" && zsh -n "$W/_btfc" && echo "ok   zsh-completion-syntax" || { echo "FAIL zsh-completion-syntax"; fails=$((fails + 1)); }
fi
if [ -n "${BUILD_DIR:-}" ] && [ -f "$BUILD_DIR/btfc.1" ]; then
  check install 0 cmake --install "$BUILD_DIR" --prefix "$W/inst" --component Unspecified
  for f in bin/btfc share/man/man1/btfc.1 share/bash-completion/completions/btfc share/zsh/site-functions/_btfc; do
    [ -s "$W/inst/$f" ] || { echo "FAIL installed: $f"; fails=$((fails + 1)); }
  done
  echo "ok   installed-files"
fi

echo "$fails failure(s)"
[ "$fails" -eq 0 ]
