#!/usr/bin/env bash
# No silent surprises, through the real binary: an image set with images missing from its UBO
# sampling is refused naming them (read with --allow-partial and a warning); an empty directory
# is a format error (exit 2); a missing input has one wording and exit 2 in every command.
# Usage: BTFC=path/to/btfc surprises_test.sh WORKDIR
set -uo pipefail
W=$1
rm -rf "$W" && mkdir -p "$W"
fails=0
source "$(dirname "$0")/cli_lib.sh"  # check, expect_grep

check synth-set 0 "$BTFC" synth --width 6 --height 5 --views 0,0 --format png -o "$W/set"
check full-set 0 "$BTFC" info "$W/set"
expect_grep full-set-desc "81 lights (ubo2003)" "$W/out.txt"
rm "$W/set/tv000_pv000/tl075_pl090_tv000_pv000.png"
check partial-refused 2 "$BTFC" info "$W/set"
expect_grep partial-named "1 of the 81 ubo2003 light directions have no image: tl075 pl090" "$W/err.txt"
expect_grep partial-hint "allow-partial" "$W/err.txt"
check partial-compress-refused 2 "$BTFC" compress "$W/set" -c fmf:rank=2 -o "$W/p.btfc"
check partial-allowed 0 "$BTFC" info "$W/set" --allow-partial
expect_grep partial-allowed-desc "80 lights (custom)" "$W/out.txt"
expect_grep partial-allowed-warning "warning: .*tl075 pl090" "$W/err.txt"
mkdir -p "$W/empty"
check empty-dir 2 "$BTFC" info "$W/empty"
expect_grep empty-dir-msg "not an image set" "$W/err.txt"
check empty-dir-compress 2 "$BTFC" compress "$W/empty" -c fmf -o "$W/e.btfc"
# One wording and one exit code for a missing input, whatever the command.
"$BTFC" synth --width 4 --height 4 -o "$W/s.btfc" -q
for cmd in "info $W/nope.btfc" "compress $W/nope.btfc -c fmf -o $W/x.btfc" "decompress $W/nope.btfc -o $W/x.btfc" \
           "eval $W/nope.btfc --texel 0,0 --light 0 --view 0" "compare $W/s.btfc $W/nope.btfc" "convert $W/nope.btfc -o $W/x.btf" \
           "export $W/nope.btfc --to $W/x" "render $W/nope.btfc -o $W/x.png" "bench $W/nope.btfc -c fmf"; do
  # shellcheck disable=SC2086
  check "missing-${cmd%% *}" 2 "$BTFC" $cmd
  expect_grep "missing-${cmd%% *}-wording" "nope.btfc: no such file or directory" "$W/err.txt"
done

# Extrapolated evaluations are said (once); measured ones are not.
check one-view-model 0 "$BTFC" compress "$W/set" --allow-partial -c fmf:rank=2 -o "$W/v1.btfc"
check eval-other-view 0 "$BTFC" eval "$W/v1.btfc" --texel 1,1 --wl 20,30 --wv 40,100
expect_grep eval-other-view-warning "extrapolated evaluation: --wv away from the model's one measured view" "$W/err.txt"
[ "$(grep -c warning "$W/err.txt")" -eq 1 ] && echo "ok   eval-warned-once" || { echo "FAIL eval-warned-once"; fails=$((fails + 1)); }
check eval-below 0 "$BTFC" eval "$W/v1.btfc" --texel 1,1 --wl 120,30 --wv 0,0
expect_grep eval-below-warning "below the horizon" "$W/err.txt"
check eval-measured-view 0 "$BTFC" eval "$W/v1.btfc" --texel 1,1 --wl 20,30 --wv 0,0
[ ! -s "$W/err.txt" ] && echo "ok   eval-no-warning" || { echo "FAIL eval-no-warning"; cat "$W/err.txt"; fails=$((fails + 1)); }

echo "$fails failure(s)"
[ "$fails" -eq 0 ]
