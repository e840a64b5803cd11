#!/usr/bin/env bash
# Writes the fuzz seeds derived from the real test data (../shared/data: the UBO2003 slice and the
# textile, README there) and from the golden models into tests/fuzz/corpus/<target>/ (issue 25).
# Their outputs are committed; run this again only to regenerate them (same data, same btfc ->
# same seeds, except JPEG re-encoding by another OpenImageIO version).
#
# Usage: tests/fuzz/make_seeds.sh [BTFC]    (default: $BTFC, else build/btfc; any normal build)
# Needs oiiotool (crops) and python3 (packing; standard library only). Every seed < 64 KiB
# (scripts/fuzz.sh runs with -max_len=65536).
#
#   crops      slice8: 8 x 8 texels of the slice, 81 lights x 1 view (JPEG, UBO2003 names)
#              textile8: 8 x 8 texels of the textile, 81 lights x 2 views (EXR, UTIA names)
#   fuzz_container / fuzz_model_load   each codec's model of each crop (model_load: byte 0 = 0)
#   fuzz_bonn           DFMF / FMF (btfc convert) of the crops' fmf models
#   fuzz_bsvtf          btfc bsvtf --tile 8 of the golden fmf models and of the crops' fmf models,
#                       and of a 24 x 24 crop of the slice (3 levels, 14 tiles)
#   fuzz_mlvq_indices   every index stream of tests/golden/mlvq.btfc and of the crops' mlvq
#                       models, with its count and alphabet (the harness's decode layout)
#   fuzz_image_set      1-4 images of 2 x 2 .. 8 x 8 texels cut from the real files, real names
set -euo pipefail
cd "$(dirname "$0")/../.."
BTFC=${1:-${BTFC:-build/btfc}}
DATA=${DATA_DIR:-../shared/data}
SLICE=$DATA/ubo2003_tv000_pv000_81lights
TEX=$DATA/textile_lurex_utia64
C=tests/fuzz/corpus
W=$(mktemp -d)
trap 'rm -rf "$W"' EXIT
for d in fuzz_container fuzz_model_load fuzz_bonn fuzz_bsvtf fuzz_mlvq_indices fuzz_image_set; do mkdir -p "$C/$d"; done
cut() { oiiotool "$1" --cut "$2" -o "$3"; }  # crop and move the origin to 0,0

# Crops (the texels at 120,120 of the slice: leather; 24,24 of the textile: a lurex crossing).
mkdir -p "$W/slice8" "$W/textile8/tv000_pv000" "$W/textile8/tv015_pv000"
for f in "$SLICE"/*.jpg; do cut "$f" 8x8+120+120 "$W/slice8/$(basename "$f")"; done
for v in tv000_pv000 tv015_pv000; do
  for f in "$TEX/$v"/*.exr; do cut "$f" 8x8+24+24 "$W/textile8/$v/$(basename "$f")"; done
done

# Each codec's model of each crop.
specs=(fmf:rank=8 fmf:color=dfmf:rank=6:chroma_rank=2:offset=1e-5 fmf:rank=6:precision=q:textures=dct lpyr:y=4:c=1 lpca:components=4:clusters=2 mlvq mlvq:layout=grid:phi=4:theta=3:alpha=5:beta=5)
names=(fmf fmf_dfmf fmf_q lpyr lpca mlvq mlvq_grid)
for crop in slice8 textile8; do
  for i in "${!specs[@]}"; do
    m="$W/${crop}_${names[$i]}.btfc"
    "$BTFC" -q compress "$W/$crop" -c "${specs[$i]}" -o "$m"
    cp "$m" "$C/fuzz_container/${crop}_${names[$i]}.btfc"
    { printf '\0'; cat "$m"; } >"$C/fuzz_model_load/${crop}_${names[$i]}"
  done
  "$BTFC" -q -f convert "$W/${crop}_fmf.btfc" -o "$C/fuzz_bonn/${crop}_fmf.btf"
  "$BTFC" -q -f convert "$W/${crop}_fmf_dfmf.btfc" -o "$C/fuzz_bonn/${crop}_dfmf.btf"
  "$BTFC" -q -f bsvtf --tile 8 "$W/${crop}_fmf.btfc" -o "$C/fuzz_bsvtf/${crop}_fmf.bsvtf"
  "$BTFC" -q -f bsvtf --tile 8 --quality 50 "$W/${crop}_fmf_dfmf.btfc" -o "$C/fuzz_bsvtf/${crop}_dfmf_q50.bsvtf"
done
# Several levels and tiles: 24 x 24 texels of the slice in 8-texel tiles (3 levels, 14 tiles).
mkdir -p "$W/slice24"
for f in "$SLICE"/*.jpg; do cut "$f" 24x24+120+120 "$W/slice24/$(basename "$f")"; done
"$BTFC" -q compress "$W/slice24" -c fmf:rank=4 -o "$W/slice24_fmf.btfc"
"$BTFC" -q -f bsvtf --tile 8 "$W/slice24_fmf.btfc" -o "$C/fuzz_bsvtf/slice24_fmf_3levels.bsvtf"
"$BTFC" -q -f bsvtf --tile 8 tests/golden/fmf.btfc -o "$C/fuzz_bsvtf/golden_fmf.bsvtf"
"$BTFC" -q -f bsvtf --tile 8 tests/golden/fmf_dfmf.btfc -o "$C/fuzz_bsvtf/golden_fmf_dfmf.bsvtf"
# A dfmf model with the offset from the data: colour model 13 (BSVTF 1.1, the offset in the header).
"$BTFC" -q -f synth --width 8 --height 8 --views 0,0 --seed 11 --scale 30 -o "$W/synth8.btfc"
"$BTFC" -q -f compress "$W/synth8.btfc" -c fmf:color=dfmf:rank=4:chroma_rank=2 -o "$W/synth8_dfmf.btfc"
"$BTFC" -q -f bsvtf --quality 50 "$W/synth8_dfmf.btfc" -o "$C/fuzz_bsvtf/synth8_dfmf_own_offset_q50.bsvtf"

# Index streams of mlvq models: tensors *.idx, merge.lum, merge.chroma, texel.idx.
python3 - "$C/fuzz_mlvq_indices" tests/golden/mlvq.btfc "$W"/*_mlvq*.btfc <<'PY'
import os, struct, sys
out = sys.argv[1]
def tensors(path):
    b = open(path, 'rb').read()
    pos, t = 32, {}
    while pos + 32 <= len(b):
        typ, size = b[pos:pos + 4], struct.unpack_from('<Q', b, pos + 8)[0]
        p = b[pos + 32:pos + 32 + size]
        if typ == b'TNSR':
            n = struct.unpack_from('<I', p, 0)[0]
            name = p[4:4 + n].decode()
            dtype, nd = p[4 + n], p[5 + n]
            dims = struct.unpack_from('<%dQ' % nd, p, 8 + n)
            h0 = 8 + n + 8 * nd
            t[name] = (dtype, dims, p[h0 + (16 - h0 % 16) % 16:])
        pos += 32 + size + (16 - size % 16) % 16
    return t
for path in sys.argv[2:]:
    t = tensors(path)
    hdr = struct.unpack('<8I', t['mlvq'][2])
    books = struct.unpack('<15I', t['books'][2])
    scheme, n, M = hdr[0], {4: hdr[1], 3: hdr[2], 2: hdr[3], 1: hdr[4]}, hdr[6]
    K = lambda p, k: books[5 * p + k]
    names = ['rgb', 'lum', 'chroma']
    streams = []
    for p in range(3):
        for k in range(2, 5):
            if K(p, k):
                alpha = M if (p == 0 and k - 1 == scheme) else K(p, k - 1)
                streams.append(('%s%d.idx' % (names[p], k), K(p, k) * n[k], alpha))
    streams += [('merge.lum', M, K(1, scheme)), ('merge.chroma', M, K(2, scheme))]
    N = 1
    for d in t['texel.scale'][1]: N *= d
    streams.append(('texel.idx', N, M if scheme == 4 else K(0, 4)))
    stem = os.path.basename(path).replace('.btfc', '')
    for name, count, alpha in streams:
        data = t[name][2]
        seed = bytes([0]) + struct.pack('<II', count, alpha) + data
        if len(seed) < 65536:
            open(os.path.join(out, '%s_%s' % ('golden_mlvq' if 'golden' in path else stem, name)), 'wb').write(seed)
PY
# Round-trip seeds: alphabet 5 and 300, Huffman allowed.
printf '\x03\x04\x00\x00\x00\x01\x00\x04\x00\x04\x00\x02\x00\x00\x00\x00\x00\x03\x00' >"$C/fuzz_mlvq_indices/roundtrip_a5"
printf '\x01\x2b\x01\x00\x00\x2b\x01\x10\x00\x10\x00\x07\x00' >"$C/fuzz_mlvq_indices/roundtrip_a300_plain"

# Image sets: entries "u8 name length, name, u16 data length, data" after one flag byte.
mkdir -p "$W/img"
s0="00000 tl000 pl000 tv000 pv000.jpg" s1="00081 tl015 pl000 tv000 pv000.jpg" s2="00162 tl015 pl060 tv000 pv000.jpg" s3="00243 tl015 pl120 tv000 pv000.jpg"
cut "$SLICE/$s0" 4x4+120+120 "$W/img/s0_4.jpg"
for s in "$s0" "$s1" "$s2" "$s3"; do cut "$SLICE/$s" 2x2+60+200 "$W/img/${s:0:5}_2.jpg"; done
t0=tl000_pl000_tv000_pv000 t1=tl015_pl000_tv000_pv000 t2=tl000_pl000_tv015_pv000 t3=tl015_pl000_tv015_pv000
cut "$TEX/tv000_pv000/$t0.exr" 2x2+24+24 "$W/img/t0_2.exr"
for t in $t0 $t1 $t2 $t3; do cut "$TEX/${t:12:11}/$t.exr" 8x8+24+24 "$W/img/${t}_8.exr"; done
oiiotool "$W/img/${t0}_8.exr" --cut 4x4+0+0 -d uint8 --tocolorspace sRGB -o "$W/img/t0_4.png"
oiiotool "$W/img/${t1}_8.exr" --cut 4x4+0+0 -d uint8 --tocolorspace sRGB -o "$W/img/t1_4.png"
python3 - "$C/fuzz_image_set" "$W/img" <<PY
import os, struct, sys
out, img = sys.argv[1], sys.argv[2]
def seed(name, flags, entries):
    b = bytes([flags])
    for fname, src in entries:
        data = open(os.path.join(img, src), 'rb').read()
        n = fname.encode()
        b += bytes([len(n)]) + n + struct.pack('<H', len(data)) + data
    assert len(b) < 65536, name
    open(os.path.join(out, name), 'wb').write(b)
seed('slice_1img_4x4', 0, [('$s0', 's0_4.jpg')])
seed('slice_4lights_2x2_viewfolder', 0, [('tv000_pv000/$s0', '00000_2.jpg'), ('tv000_pv000/$s1', '00081_2.jpg'),
                                         ('tv000_pv000/$s2', '00162_2.jpg'), ('tv000_pv000/$s3', '00243_2.jpg')])
seed('slice_missing_pair_partial', 1, [('$s1', '00081_2.jpg'), ('$s2', '00162_2.jpg')])
seed('textile_1img_2x2', 2, [('tv000_pv000/$t0.exr', 't0_2.exr')])
seed('textile_2x2dirs_8x8', 0, [('tv000_pv000/$t0.exr', '${t0}_8.exr'), ('tv000_pv000/$t1.exr', '${t1}_8.exr'),
                                ('tv015_pv000/$t2.exr', '${t2}_8.exr'), ('tv015_pv000/$t3.exr', '${t3}_8.exr')])
seed('textile_png_2lights_4x4', 0, [('$t0.png', 't0_4.png'), ('$t1.png', 't1_4.png')])
seed('mixed_exr_png_sizes', 0, [('$t0.exr', 't0_2.exr'), ('$t1.png', 't1_4.png')])
seed('duplicate_angles', 0, [('$s0', 's0_4.jpg'), ('tv000_pv000/$s0', 's0_4.jpg')])
PY

# Spec strings: every codec with every parameter of its table (btfc codecs).
S=tests/fuzz/corpus/fuzz_spec
printf 'fmf:rank=16:chroma_rank=4:target_error=0.01:color=dfmf:svd=randomized:oversample=8:power_iters=3:precision=q:bits=10:textures=dct:offset=1e-5' >"$S/fmf_all"
printf 'lpyr:levels=3:y=6:c=2:basis_ratio=32:mean=phong:laplacian_mean=keep:precision=q:bits=9' >"$S/lpyr_all"
printf 'lpca:clusters=4:components=6:iters=5:precision=q:bits=7:sh_order=4' >"$S/lpca_all"
printf 'mlvq:scheme=2:ssim4=0.96:ssim3=0.94:ssim2=0.92:ssim1=0.9:chroma=2.5:layout=grid:phi=8:theta=5:alpha=9:beta=7:value_bits=10:huffman=off:scale_bits=12:noise=off:min_ratio=20' >"$S/mlvq_all"
printf 'mlvq:scheme=best:layout=measured:value_bits=0:scale_bits=auto:huffman=auto:noise=auto:min_ratio=0' >"$S/mlvq_choices"

for f in "$C"/*/*; do
  [ "$(stat -c %s "$f")" -lt 65536 ] || { echo "make_seeds.sh: $f is $(stat -c %s "$f") bytes (>= 64 KiB)" >&2; exit 1; }
done
echo "seeds written under $C"
