#!/usr/bin/env bash
# Out-of-core CLI checks through the real binary: `compress --max-memory` on a BTF larger than
# the limit streams (same factorization as in core, peak RSS under limit + overhead), the
# working file is a valid Bonn BDI, an interrupted working file is detected and rebuilt,
# color=dfmf and svd=exact stream too, and `decompress -o OUT.btf / OUT.btfc` streams. Usage: BTFC=path/to/btfc stream_test.sh WORKDIR
set -uo pipefail
W=$1
rm -rf "$W" && mkdir -p "$W"
fails=0
source "$(dirname "$0")/cli_lib.sh"  # check, expect_grep
# Under AddressSanitizer (scripts/test-sanitize.sh) the peak-RSS bounds cannot hold: its shadow
# memory and quarantine add to every process. Everything else is checked as usual.
[ "${BTFC_SANITIZER:-0}" = 1 ] && echo "note: peak-RSS bounds skipped under the sanitizer (BTFC_SANITIZER=1)"

# 56 x 56 texels x 81 x 81 x RGB = 61.7 M values = 247 MB as float32; limit 40 MiB.
SPEC=fmf:rank=16:oversample=8:power_iters=2
check synth 0 "$BTFC" synth --width 56 --height 56 --seed 5 -o "$W/s.btfc"
check in-core 0 "$BTFC" -q compress "$W/s.btfc" -c $SPEC -o "$W/in.btfc"
check ooc 0 "$BTFC" --json compress "$W/s.btfc" -c $SPEC -o "$W/ooc.btfc" --max-memory 40M
cp "$W/out.txt" "$W/ooc.json"
ls -a "$W" | grep -q '\.btfc-work-' && { echo "FAIL temp-work-file-left"; fails=$((fails + 1)); }
check cmp-in 0 "$BTFC" --json compare --no-ssim "$W/s.btfc" "$W/in.btfc"
cp "$W/out.txt" "$W/cmp_in.json"
check cmp-ooc 0 "$BTFC" --json compare --no-ssim "$W/s.btfc" "$W/ooc.btfc"
cp "$W/out.txt" "$W/cmp_ooc.json"
# Peak RSS bound: limit + the fixed overhead docs/scaling.md states (200 MiB: 135 MiB at
# process start, mostly OpenImageIO's shared libraries, plus thread stacks and BLAS buffers).
# In core the same run needs the 247 MB input on top of the start-up 135 MiB.
python3 - "$W" <<'PY' || fails=$((fails + 1))
import json, os, sys
SAN = os.environ.get("BTFC_SANITIZER") == "1"  # ASan shadow memory and quarantine: no RSS bound holds
w = sys.argv[1]
r = json.load(open(w + "/ooc.json"))
o = r["out_of_core"]
assert o["passes"] == 4, o                      # power_iters + 2
assert o["work_file_built"] and o["chunks"] >= 2, o
assert o["bytes_read"] == 4 * 56 * 56 * 19683 * 2, o   # 4 passes over the half working file
limit, overhead = 40 << 20, 200 << 20
assert SAN or o["peak_rss_bytes"] <= limit + overhead, (o["peak_rss_bytes"], limit + overhead)
a = json.load(open(w + "/cmp_in.json"))["rel_l2"]; b = json.load(open(w + "/cmp_ooc.json"))["rel_l2"]
assert 1e-3 < a < 0.5, a
assert abs(a - b) / a < 0.01, (a, b)
print("ok   ooc-vs-in-core rel_l2 %.6f vs %.6f, peak RSS %.1f MiB (limit 40 MiB + 200 MiB overhead)" % (a, b, o["peak_rss_bytes"] / 2**20))
PY

# With room for float chunks (12 bytes per value) a raw .btfc is streamed in place: no working
# file, the same factorization, and its CRC still checked (a flipped bit is an error, no output).
check ooc-raw 0 "$BTFC" --json compress "$W/s.btfc" -c $SPEC -o "$W/ooc_raw.btfc" --max-memory 80M
cp "$W/out.txt" "$W/ooc_raw.json"
check cmp-ooc-raw 0 "$BTFC" --json compare --no-ssim "$W/s.btfc" "$W/ooc_raw.btfc"
cp "$W/out.txt" "$W/cmp_ooc_raw.json"
python3 - "$W" <<'PY' || fails=$((fails + 1))
import json, os, sys
SAN = os.environ.get("BTFC_SANITIZER") == "1"  # ASan shadow memory and quarantine: no RSS bound holds
w = sys.argv[1]
o = json.load(open(w + "/ooc_raw.json"))["out_of_core"]
assert not o["work_file_built"] and "in place" in o["work_file_note"] and o["chunks"] >= 2, o
assert o["bytes_read"] == 4 * 56 * 56 * 19683 * 4, o   # 4 passes over the float tensor
assert SAN or o["peak_rss_bytes"] <= (80 << 20) + (200 << 20), o["peak_rss_bytes"]
a = json.load(open(w + "/cmp_in.json"))["rel_l2"]; b = json.load(open(w + "/cmp_ooc_raw.json"))["rel_l2"]
assert abs(a - b) / a < 0.01, (a, b)
print("ok   ooc-raw-in-place rel_l2 %.6f vs in core %.6f, peak RSS %.1f MiB" % (b, a, o["peak_rss_bytes"] / 2**20))
PY
cp "$W/s.btfc" "$W/flip.btfc"
python3 -c "import os,sys; p=sys.argv[1]; n=os.path.getsize(p); f=open(p,'r+b'); f.seek(n//2); b=f.read(1); f.seek(n//2); f.write(bytes([b[0]^16]))" "$W/flip.btfc"
check ooc-raw-crc 2 "$BTFC" compress "$W/flip.btfc" -c $SPEC -o "$W/flip.fmf.btfc" --max-memory 80M
expect_grep ooc-raw-crc-msg "CRC mismatch" "$W/err.txt"
[ ! -e "$W/flip.fmf.btfc" ] && echo "ok   ooc-raw-crc-no-output" || { echo "FAIL ooc-raw-crc-no-output"; fails=$((fails + 1)); }
# The same for color=dfmf (the channel sources hand the first-pass CRC check to the raw source).
check ooc-raw-crc-dfmf 2 "$BTFC" compress "$W/flip.btfc" -c fmf:color=dfmf:rank=8:oversample=8:power_iters=1 -o "$W/flip.fmf.btfc" --max-memory 80M
expect_grep ooc-raw-crc-dfmf-msg "CRC mismatch" "$W/err.txt"

# A kept working file is a Bonn BDI btfc reads as a BTF; the second run reuses it.
check keep 0 "$BTFC" --json compress "$W/s.btfc" -c $SPEC -o "$W/k.btfc" --work-file "$W/work.btf" --max-memory 40M
check info-work 0 "$BTFC" info "$W/work.btf"
expect_grep work-is-bdi "BDI" "$W/out.txt"
check reuse 0 "$BTFC" --json compress "$W/s.btfc" -c $SPEC -o "$W/k2.btfc" --work-file "$W/work.btf" --max-memory 40M
expect_grep reused '"work_file_reused": true' "$W/out.txt"
# An interrupted run leaves the placeholder signature: detected, not trusted, rebuilt.
printf '#BTFCPART!' | dd of="$W/work.btf" bs=1 count=10 conv=notrunc status=none
check info-interrupted 2 "$BTFC" info "$W/work.btf"
expect_grep interrupted-msg "incomplete working file" "$W/err.txt"
check rebuild 0 "$BTFC" --json compress "$W/s.btfc" -c $SPEC -o "$W/k3.btfc" --work-file "$W/work.btf" --max-memory 40M
expect_grep rebuilt '"work_file_built": true' "$W/out.txt"
expect_grep rebuilt-note 'incomplete working file.*rebuilt' "$W/out.txt"
check cmp-rebuilt 0 "$BTFC" --json compare --no-ssim "$W/k.btfc" "$W/k3.btfc"
python3 -c "import json,sys; m=json.load(open('$W/out.txt')); assert m['rel_l2'] < 1e-6, m; print('ok   rebuilt-same-model', m['rel_l2'])" || fails=$((fails + 1))

# Only fmf streams; a limit too small for one texel row is an error.
check other-codec 1 "$BTFC" compress "$W/s.btfc" -c lpyr -o "$W/x.btfc" --max-memory 40M
expect_grep other-codec-msg "fmf compresses out of core" "$W/err.txt"
check too-small 1 "$BTFC" compress "$W/s.btfc" -c $SPEC -o "$W/x.btfc" --max-memory 1M
check bad-size 1 "$BTFC" compress "$W/s.btfc" -c $SPEC -o "$W/x.btfc" --max-memory 12Q
[ -e "$W/x.btfc" ] && { echo "FAIL partial-output"; fails=$((fails + 1)); }

# in_and_out_of_core TAG INPUT SPEC LIMIT: compresses in core and with --max-memory LIMIT and
# compares both with the input: leaves $W/TAG.ooc.json (the streamed run's report),
# $W/TAG.cmp_in.json (in core vs input) and out.txt (out of core vs input).
in_and_out_of_core() {
  local tag=$1 in=$2 spec=$3 limit=$4
  check "$tag-in-core" 0 "$BTFC" -q compress "$in" -c "$spec" -o "$W/$tag.in.btfc"
  check "$tag-ooc" 0 "$BTFC" --json compress "$in" -c "$spec" -o "$W/$tag.ooc.btfc" --max-memory "$limit"
  cp "$W/out.txt" "$W/$tag.ooc.json"
  check "$tag-cmp-in" 0 "$BTFC" --json compare --no-ssim "$in" "$W/$tag.in.btfc"
  cp "$W/out.txt" "$W/$tag.cmp_in.json"
  check "$tag-cmp-ooc" 0 "$BTFC" --json compare --no-ssim "$in" "$W/$tag.ooc.btfc"
}

# color=dfmf streams too: three channel factorizations in one stream (power_iters + 2 = 4 passes)
# over the same working file,
# the error of the in-core dfmf, the clamp statistic, and the memory bound.
DSPEC=fmf:color=dfmf:rank=12:chroma_rank=6:oversample=8:power_iters=2:svd=randomized
check synth-32 0 "$BTFC" synth --width 32 --height 32 --seed 5 -o "$W/s32.btfc"
in_and_out_of_core dfmf "$W/s32.btfc" $DSPEC 30M
python3 - "$W" <<'PY' || fails=$((fails + 1))
import json, os, sys
SAN = os.environ.get("BTFC_SANITIZER") == "1"  # ASan shadow memory and quarantine: no RSS bound holds
w = sys.argv[1]
r = json.load(open(w + "/dfmf.ooc.json")); o = r["out_of_core"]; st = r["stats"]
assert o["passes"] == 4 and o["chunks"] >= 2, o   # one stream: power_iters + 2
# The BTF read once per pass: in place (float) or from a half working file.
assert o["bytes_read"] == 4 * 32 * 32 * 19683 * (2 if o["work_file_built"] else 4), o
assert SAN or o["peak_rss_bytes"] <= (30 << 20) + (200 << 20), o["peak_rss_bytes"]
assert st["rank.y"] == 12 and st["rank.u"] == 6 and "negative_luminance_clamped" in st, st
a = json.load(open(w + "/dfmf.cmp_in.json"))["rel_l2"]; b = json.load(open(w + "/out.txt"))["rel_l2"]
assert 1e-3 < a < 0.9 and abs(a - b) / a < 0.01, (a, b)
print("ok   dfmf-ooc-vs-in-core rel_l2 %.6f vs %.6f, peak RSS %.1f MiB" % (b, a, o["peak_rss_bytes"] / 2**20))
PY

# svd=exact streams in 2 passes when the rows x rows Gram matrix fits (81 lights x 1 view: 243
# rows, 32768 texels, 32 MB > 30 MiB), and is refused, naming the sizes, when it does not.
check synth-1view 0 "$BTFC" synth --width 256 --height 128 --views 30,0 --seed 3 -o "$W/v1.btfc"
in_and_out_of_core exact "$W/v1.btfc" fmf:rank=16:svd=exact 30M
python3 - "$W" <<'PY' || fails=$((fails + 1))
import json, os, sys
SAN = os.environ.get("BTFC_SANITIZER") == "1"  # ASan shadow memory and quarantine: no RSS bound holds
w = sys.argv[1]
r = json.load(open(w + "/exact.ooc.json")); o = r["out_of_core"]
assert o["passes"] == 2 and o["chunks"] >= 2 and r["stats"]["svd.rgb"] == "exact (streamed)", r
assert SAN or o["peak_rss_bytes"] <= (30 << 20) + (200 << 20), o["peak_rss_bytes"]
a = json.load(open(w + "/exact.cmp_in.json"))["rel_l2"]; b = json.load(open(w + "/out.txt"))["rel_l2"]
assert 1e-3 < a < 0.5 and abs(a - b) / a < 1e-4, (a, b)   # the same factorization (half rounding of the working file aside)
print("ok   exact-ooc-vs-in-core rel_l2 %.7f vs %.7f in 2 passes" % (b, a))
PY
# Its model (32 MB decoded) decompressed to an image set within 8 MiB: written in parts (groups of
# lights), the same images as an in-memory decompress, and the set appears only when complete.
check decompress-images 0 "$BTFC" --device cpu --json decompress "$W/exact.ooc.btfc" -o "$W/img_streamed" --max-memory 8M
python3 -c "import json, os; m=json.load(open('$W/out.txt')); assert m['format'] == 'image set' and (os.environ.get('BTFC_SANITIZER') == '1' or m['peak_rss_bytes'] <= (8 << 20) + (200 << 20)), m; print('ok   images-streamed peak RSS %.1f MiB' % (m['peak_rss_bytes'] / 2**20))" || fails=$((fails + 1))
check decompress-images-in-memory 0 "$BTFC" --device cpu -q decompress "$W/exact.ooc.btfc" -o "$W/img_whole"
check cmp-images 0 "$BTFC" --json compare --no-ssim "$W/img_whole" "$W/img_streamed"
python3 -c "import json; m=json.load(open('$W/out.txt')); assert m['rel_l2'] == 0, m; print('ok   images-streamed-identical')" || fails=$((fails + 1))
[ "$(ls "$W/img_streamed"/*/ | grep -c exr)" = 81 ] && echo "ok   images-streamed-count" || { echo "FAIL images-streamed-count"; fails=$((fails + 1)); }
ls -d "$W"/img_streamed.tmp-* >/dev/null 2>&1 && { echo "FAIL images-streamed-temp-left"; fails=$((fails + 1)); }
check exact-too-big 1 "$BTFC" compress "$W/s.btfc" -c fmf:rank=16:svd=exact -o "$W/x.btfc" --max-memory 40M
expect_grep exact-too-big-msg "svd=exact needs the 19683 x 19683 Gram matrix" "$W/err.txt"
[ -e "$W/x.btfc" ] && { echo "FAIL exact-partial-output"; fails=$((fails + 1)); }

# HDR beyond the half range: the working file restarts with a power-of-two scale.
check synth-hdr 0 "$BTFC" synth --width 12 --height 10 --scale 1e6 -o "$W/h.btfc"
check ooc-hdr 0 "$BTFC" --json compress "$W/h.btfc" -c fmf:rank=8 -o "$W/h.fmf.btfc" --work-file "$W/hw.btf"
expect_grep hdr-scale 'restarted with scale' "$W/out.txt"
check in-core-hdr 0 "$BTFC" -q compress "$W/h.btfc" -c fmf:rank=8:svd=randomized -o "$W/h.in.btfc"
check cmp-hdr-in 0 "$BTFC" --json compare --no-ssim "$W/h.btfc" "$W/h.in.btfc"
cp "$W/out.txt" "$W/hin.json"
check cmp-hdr 0 "$BTFC" --json compare --no-ssim "$W/h.btfc" "$W/h.fmf.btfc"
python3 -c "
import json; a=json.load(open('$W/hin.json'))['rel_l2']; b=json.load(open('$W/out.txt'))['rel_l2']
assert 1e-4 < a < 0.5 and abs(a - b) / a < 0.01, (a, b); print('ok   hdr-error in core %.6f, out of core %.6f' % (a, b))" || fails=$((fails + 1))

# An image set (81 EXR images, one view) streams into the working file image by image.
check synth-set 0 "$BTFC" synth --width 20 --height 16 --views 30,0 -o "$W/set"
check set-in-core 0 "$BTFC" -q compress "$W/set" -c fmf:rank=8:svd=randomized -o "$W/set.in.btfc"
check set-ooc 0 "$BTFC" --json compress "$W/set" -c fmf:rank=8 -o "$W/set.ooc.btfc" --work-file "$W/setw.btf"
expect_grep set-built '"work_file_built": true' "$W/out.txt"
check set-cmp-in 0 "$BTFC" --json compare --no-ssim "$W/set" "$W/set.in.btfc"
cp "$W/out.txt" "$W/setin.json"
check set-cmp-ooc 0 "$BTFC" --json compare --no-ssim "$W/set" "$W/set.ooc.btfc"
python3 -c "
import json; a=json.load(open('$W/setin.json'))['rel_l2']; b=json.load(open('$W/out.txt'))['rel_l2']
assert 1e-4 < a < 0.5 and abs(a - b) / a < 0.01, (a, b); print('ok   image-set in core %.6f, out of core %.6f' % (a, b))" || fails=$((fails + 1))

# decompress to a Bonn BDI or a raw .btfc streams texel bands (the .btfc byte for byte the
# in-memory one, its CRC written last); an image set streams in groups of images (below).
check decompress-bdi 0 "$BTFC" --json decompress "$W/ooc.btfc" -o "$W/d.btf" --max-memory 8M
check cmp-bdi 0 "$BTFC" --json compare --no-ssim "$W/ooc.btfc" "$W/d.btf"
python3 -c "import json; m=json.load(open('$W/out.txt')); assert m['rel_l2'] < 2e-3, m; print('ok   bdi-decoded', m['rel_l2'])" || fails=$((fails + 1))
check decompress-btfc 0 "$BTFC" --device cpu --json decompress "$W/ooc.btfc" -o "$W/d2.btfc" --max-memory 8M
python3 -c "import json, os; m=json.load(open('$W/out.txt')); assert m['format'] == 'raw .btfc' and (os.environ.get('BTFC_SANITIZER') == '1' or m['peak_rss_bytes'] <= (8 << 20) + (200 << 20)), m; print('ok   btfc-streamed peak RSS %.1f MiB' % (m['peak_rss_bytes'] / 2**20))" || fails=$((fails + 1))
check decompress-btfc-in-memory 0 "$BTFC" --device cpu -q decompress "$W/ooc.btfc" -o "$W/d3.btfc"
cmp -s "$W/d2.btfc" "$W/d3.btfc" && echo "ok   btfc-streamed-identical" || { echo "FAIL btfc-streamed-identical"; fails=$((fails + 1)); }
check decompress-btfc-verify 0 "$BTFC" info --verify "$W/d2.btfc"
# An image set whose one image does not fit the limit: refused, nothing left behind.
check decompress-image-too-big 1 "$BTFC" decompress "$W/ooc.btfc" -o "$W/dimg" --max-memory 10K
[ -e "$W/dimg" ] && { echo "FAIL decompress-too-big-output"; fails=$((fails + 1)); }
# A given --max-memory is also the in-core limit: a region decode beyond it is refused, one within it runs.
check decompress-region-limit 1 "$BTFC" decompress "$W/ooc.btfc" -o "$W/r.btfc" --region 0,0,40,40 --max-memory 8M
expect_grep decompress-region-msg "over the memory limit of 8388608 bytes" "$W/err.txt"
check decompress-region-fits 0 "$BTFC" -q decompress "$W/ooc.btfc" -o "$W/r.btfc" --region 0,0,8,8 --max-memory 8M
check bench-ooc 0 "$BTFC" --json bench "$W/s.btfc" -c $SPEC --max-memory 40M
python3 -c "import json; r=json.load(open('$W/out.txt'))[0]; assert 1e-3 < r['rel_l2'] < 0.5 and r['out_of_core']['passes'] == 4, r; print('ok   bench-ooc', r['rel_l2'])" || fails=$((fails + 1))
cp "$W/out.txt" "$W/bench_ooc.json"
# With room for float chunks the raw .btfc is streamed in place, and bench compares against it.
check bench-ooc-raw 0 "$BTFC" --json bench "$W/s.btfc" -c $SPEC --max-memory 80M
python3 -c "
import json; r=json.load(open('$W/out.txt'))[0]; w=json.load(open('$W/bench_ooc.json'))[0]
assert 'in place' in r['out_of_core']['work_file_note'], r
assert abs(r['rel_l2'] - w['rel_l2']) / w['rel_l2'] < 0.01, (r['rel_l2'], w['rel_l2'])
print('ok   bench-ooc-raw', r['rel_l2'])" || fails=$((fails + 1))

rm -rf "$W"
[ "$fails" -eq 0 ] && echo "all stream checks passed" || echo "$fails stream checks FAILED"
exit $((fails > 0))
