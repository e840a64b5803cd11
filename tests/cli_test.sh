#!/usr/bin/env bash
# CLI round trip through the real binary: synth -> compress -> info -> decompress -> compare,
# eval, plus the exit codes and "no partial output" rules for bad input.
# Usage: BTFC=path/to/btfc cli_test.sh WORKDIR
set -uo pipefail
W=$1
rm -rf "$W" && mkdir -p "$W"
fails=0
source "$(dirname "$0")/cli_lib.sh"  # check, expect_grep

check synth 0 "$BTFC" synth --width 12 --height 10 --seed 3 -o "$W/s.btfc"
check compress 0 "$BTFC" compress "$W/s.btfc" -c fmf:rank=12 -o "$W/m.btfc"
check info 0 "$BTFC" info --verify "$W/m.btfc"
expect_grep info-spec "fmf:rank=12" "$W/out.txt"
expect_grep info-desc "12x10 texels, 81 lights (ubo2003) x 81 views (ubo2003)" "$W/out.txt"
check info-json 0 "$BTFC" --json info "$W/m.btfc"
expect_grep info-json-codec '"codec": "fmf"' "$W/out.txt"
check decompress 0 "$BTFC" decompress "$W/m.btfc" -o "$W/d.btfc"
check compare 0 "$BTFC" --json compare "$W/s.btfc" "$W/d.btfc"
# rank 12 of a 12x10 synthetic BTF: relative error must be small but not zero.
python3 - "$W/out.txt" <<'PY' || fails=$((fails + 1))
import json, sys
m = json.load(open(sys.argv[1]))
assert 1e-5 < m["rel_l2"] < 0.2, m
assert 0.5 < m["mean_ssim"] <= 1.0, m
print("ok   compare-values", m["rel_l2"], m["mean_ssim"])
PY
check compare-model 0 "$BTFC" compare "$W/s.btfc" "$W/m.btfc"
check decompress-region 0 "$BTFC" decompress "$W/m.btfc" -o "$W/r.btfc" --region 2,3,4,5 --lights 0,5 --views 7
check info-region 0 "$BTFC" info "$W/r.btfc"
expect_grep region-desc "4x5 texels, 2 lights (custom) x 1 views (custom)" "$W/out.txt"
check eval-measured 0 "$BTFC" eval "$W/m.btfc" --texel 3,4 --light 5 --view 7
check eval-dir 0 "$BTFC" eval "$W/m.btfc" --texel 3,4 --wl 20,30 --wv 40,100
check decompress-images 0 "$BTFC" decompress "$W/m.btfc" -o "$W/imgs" --lights 0,1 --views 0
test -f "$W/imgs/tv000_pv000/tl015_pl000_tv000_pv000.exr" && echo "ok   image-set-written" || { echo "FAIL image-set-written"; fails=$((fails + 1)); }
check compare-imageset 0 "$BTFC" compare "$W/imgs" "$W/imgs"

# Bonn .btf: write DFMF / FMF from fmf models, read them back as models, convert.
check bonn-dfmf 0 "$BTFC" compress "$W/s.btfc" -c fmf:color=dfmf:rank=8:chroma_rank=4:offset=1e-5 -o "$W/m.btf"
check bonn-info 0 "$BTFC" info "$W/m.btf"
expect_grep bonn-info-sig "!DFMF08FCR" "$W/out.txt"
check bonn-fmf 0 "$BTFC" compress "$W/s.btfc" -c fmf:rank=8 -o "$W/f.btf"
check bonn-compare 0 "$BTFC" --json compare "$W/s.btfc" "$W/m.btf"
python3 -c "import json,sys; m=json.load(open(sys.argv[1])); assert 1e-4 < m['rel_l2'] < 0.5, m; print('ok   bonn-values', m['rel_l2'])" "$W/out.txt" || fails=$((fails + 1))
check bonn-eval 0 "$BTFC" eval "$W/m.btf" --texel 2,2 --wl 20,30 --wv 40,100
check bonn-recompress 0 "$BTFC" compress "$W/m.btf" -c lpyr -o "$W/l.btfc"
check bonn-convert 0 "$BTFC" convert "$W/m.btf" -o "$W/m2.btfc"
check bonn-convert-back 0 "$BTFC" convert "$W/m2.btfc" -o "$W/m3.btf"
check bonn-same 0 "$BTFC" --json compare "$W/m.btf" "$W/m3.btf"
python3 -c "import json,sys; m=json.load(open(sys.argv[1])); assert m['rmse'] == 0, m; print('ok   bonn-convert-exact')" "$W/out.txt" || fails=$((fails + 1))
# mlvq: compress (the grid layout, default scheme 4) -> info -> decompress -> compare, eval.
# (rel_l2 < 0.5: the grid at the issue-22 defaults, noise=auto caps level 1 at 0.7 on synthetic data; measured 0.40)
check mlvq-compress 0 "$BTFC" compress "$W/s.btfc" -c mlvq:phi=8:theta=4:alpha=7:beta=7 -o "$W/q.btfc"
check mlvq-info 0 "$BTFC" info --verify "$W/q.btfc"
expect_grep mlvq-info-huffman "huffman_gain" "$W/out.txt"
check mlvq-decompress 0 "$BTFC" decompress "$W/q.btfc" -o "$W/qd.btfc"
check mlvq-compare 0 "$BTFC" --json compare "$W/s.btfc" "$W/qd.btfc"
python3 -c "import json,sys; m=json.load(open(sys.argv[1])); assert 0.01 < m['rel_l2'] < 0.5 and 0.3 < m['mean_ssim'] < 1, m; print('ok   mlvq-values', m['rel_l2'], m['mean_ssim'])" "$W/out.txt" || fails=$((fails + 1))
check mlvq-eval-dir 0 "$BTFC" eval "$W/q.btfc" --texel 3,4 --wl 20,30 --wv 40,100
check mlvq-export 0 "$BTFC" export "$W/q.btfc" --to "$W/qx"
python3 -c "import json,os,sys; d=sys.argv[1]; m=json.load(open(d+'/manifest.json')); assert m['codec']=='mlvq' and m['evaluation']['grid']['nphi']==8, m['evaluation']; [os.stat(d+'/'+t['file']) for t in m['textures']]; assert open(d+'/btf.frag').read().startswith('#version 300 es'); print('ok   mlvq-export-files', len(m['textures']))" "$W/qx" || fails=$((fails + 1))
head -c 300 "$W/q.btfc" > "$W/qtrunc.btfc"
check mlvq-truncated 2 "$BTFC" decompress "$W/qtrunc.btfc" -o "$W/qt.btfc"
expect_grep mlvq-truncated-msg "qtrunc.btfc" "$W/err.txt"
head -c 40 "$W/m.btf" > "$W/trunc.btf"
check bonn-truncated 2 "$BTFC" info "$W/trunc.btf"
expect_grep bonn-truncated-msg "trunc.btf" "$W/err.txt"

# Usage errors: exit 1, nothing written.
check unknown-param 1 "$BTFC" compress "$W/s.btfc" -c fmf:rnak=3 -o "$W/bad.btfc"
expect_grep unknown-param-msg "unknown parameter 'rnak'" "$W/err.txt"
check out-of-range 1 "$BTFC" compress "$W/s.btfc" -c fmf:rank=0 -o "$W/bad.btfc"
check unknown-codec 1 "$BTFC" compress "$W/s.btfc" -c nope -o "$W/bad.btfc"
check eval-outside 1 "$BTFC" eval "$W/m.btfc" --texel 99,0 --light 0 --view 0
check no-subcommand 1 "$BTFC"
# I/O and format errors: exit 2, the message names the file.
check missing-input 2 "$BTFC" compress "$W/nope.btfc" -c fmf -o "$W/bad.btfc"
expect_grep missing-msg "nope.btfc" "$W/err.txt"
head -c 100 "$W/m.btfc" > "$W/trunc.btfc"
check truncated 2 "$BTFC" info "$W/trunc.btfc"
expect_grep truncated-msg "trunc.btfc" "$W/err.txt"
printf 'NOTABTFC at all, just text' > "$W/magic.btfc"
check wrong-magic 2 "$BTFC" decompress "$W/magic.btfc" -o "$W/bad.btfc"
test ! -e "$W/bad.btfc" && echo "ok   no-partial-output" || { echo "FAIL no-partial-output"; fails=$((fails + 1)); }
ls "$W" | grep -q tmp- && { echo "FAIL temp files left"; fails=$((fails + 1)); } || echo "ok   no-temp-files"

# Memory limit (core/limits.h): the 12x10 decode needs 9.4 MB; under a 2 MiB limit decompress
# fails before allocating (exit 1: the limit is a parameter), leaves no output, names the limit;
# a 4x4 region (1.3 MB) still decodes under it.
check max-memory 1 env BTFC_MAX_MEMORY=2M "$BTFC" decompress "$W/m.btfc" -o "$W/limited.btfc"
expect_grep max-memory-msg "memory limit" "$W/err.txt"
test ! -e "$W/limited.btfc" && echo "ok   max-memory-no-output" || { echo "FAIL max-memory-no-output"; fails=$((fails + 1)); }
check max-memory-region 0 env BTFC_MAX_MEMORY=2M "$BTFC" decompress "$W/m.btfc" -o "$W/limited.btfc" --region 0,0,4,4

# The real measured slice, when present: read, compress, compare.
if [ -d "${DATA_DIR:-}/ubo2003_tv000_pv000_81lights" ]; then
  check real-info 0 "$BTFC" info "$DATA_DIR/ubo2003_tv000_pv000_81lights"
  expect_grep real-desc "256x256 texels, 81 lights (ubo2003) x 1 views" "$W/out.txt"
  check real-compress 0 "$BTFC" compress "$DATA_DIR/ubo2003_tv000_pv000_81lights" -c fmf:rank=16 -o "$W/real.btfc"
  check real-compare 0 "$BTFC" --json compare "$DATA_DIR/ubo2003_tv000_pv000_81lights" "$W/real.btfc"
  python3 -c "import json,sys; m=json.load(open(sys.argv[1])); assert 0.005 < m['rel_l2'] < 0.2 and m['mean_ssim'] > 0.8, m; print('ok   real-values', m)" "$W/out.txt" || fails=$((fails + 1))
fi

# bench: sweeps, CSV / JSON reports, side-by-side renders, Pareto fronts, determinism.
check bench-sweep 0 "$BTFC" -q bench "$W/s.btfc" -c fmf:rank=2,6 -c lpca:clusters=2:components=2 --csv "$W/b.csv" --json-out "$W/b.json" --renders "$W/rend" --pareto --throughput-queries 2000
expect_grep bench-pareto "Pareto front by psnr" "$W/out.txt"
python3 - "$W/b.csv" "$W/b.json" <<'PY' || fails=$((fails + 1))
import csv, json, sys
rows = list(csv.DictReader(open(sys.argv[1])))
assert [r["spec_given"] for r in rows] == ["fmf:rank=2", "fmf:rank=6", "lpca:clusters=2:components=2"], rows
assert float(rows[1]["psnr"]) > float(rows[0]["psnr"]) and int(rows[1]["payload_bytes"]) > int(rows[0]["payload_bytes"]), rows
for r in rows:
    assert 0 < float(r["render_ssim"]) <= 1 and float(r["evals_per_s"]) > 0 and float(r["peak_rss_mb"]) > 0, r
    assert "bench" in r["command"] and r["machine"], r
j = json.load(open(sys.argv[2]))
assert len(j["runs"]) == 3 and j["btfc_version"] and j["machine"], j
print("ok   bench-reports")
PY
[ -f "$W/rend/s.btfc-0-fmf_rank=2-flat.png" ] && [ -f "$W/rend/s.btfc-2-lpca_clusters=2_components=2-sphere.png" ] && echo "ok   bench-renders" || { echo "FAIL bench-renders"; ls "$W/rend"; fails=$((fails + 1)); }
check bench-again 0 "$BTFC" -q bench "$W/s.btfc" -c fmf:rank=2 --csv "$W/b2.csv" --no-renders --throughput-queries 0
python3 -c "import csv,sys; a=list(csv.DictReader(open(sys.argv[1])))[0]; b=list(csv.DictReader(open(sys.argv[2])))[0]; assert a['tensor_digest']==b['tensor_digest'] and a['rmse']==b['rmse'], (a,b); print('ok   bench-deterministic')" "$W/b.csv" "$W/b2.csv" || fails=$((fails + 1))
check bench-bad-sweep 1 "$BTFC" bench "$W/s.btfc" -c fmf:rank=2,,4
check bench-bad-range 1 "$BTFC" bench "$W/s.btfc" -c fmf:rank=0,4
# budget targeting
check target-psnr 0 "$BTFC" --json compress "$W/s.btfc" -c fmf -o "$W/t.btfc" --target-psnr 30
python3 -c "import json,sys; j=json.load(open(sys.argv[1])); t=j['target']; assert t['knob']=='rank' and t['reached']>=30, t; print('ok   target-psnr-values', t['value'], t['reached'])" "$W/out.txt" || fails=$((fails + 1))
check target-unreachable 1 "$BTFC" compress "$W/s.btfc" -c fmf:precision=half -o "$W/t2.btfc" --target-psnr 500
[ ! -e "$W/t2.btfc" ] && echo "ok   target-no-output" || { echo "FAIL target-no-output"; fails=$((fails + 1)); }
check target-two 1 "$BTFC" compress "$W/s.btfc" -c fmf -o "$W/t3.btfc" --target-psnr 30 --max-bytes 1000
# BSVTF streaming file and the tile-cache simulator
check bsvtf 0 "$BTFC" --json bsvtf "$W/m.btfc" -o "$W/m.bsvtf" --quality 80 --tile 8
python3 -c "import json,sys; j=json.load(open(sys.argv[1])); assert j['textures']==3 and j['levels']==2 and 20<j['psnr']<80 and j['ratio_vs_f32']>1, j; print('ok   bsvtf-values', j['psnr'], j['ratio_vs_f32'])" "$W/out.txt" || fails=$((fails + 1))
check tilecache 0 "$BTFC" tilecache "$W/m.bsvtf" --frames 3 --cache-tiles 3,100 --screen 32x24 --csv "$W/tc.csv"
expect_grep tilecache-csv "^100,2," "$W/tc.csv"
check bsvtf-raw-input 1 "$BTFC" bsvtf "$W/s.btfc" -o "$W/bad.bsvtf"
[ ! -e "$W/bad.bsvtf" ] && echo "ok   bsvtf-no-output" || { echo "FAIL bsvtf-no-output"; fails=$((fails + 1)); }
# Models of other codecs: refused by the file's name and codec, nothing written.
check bsvtf-lpyr 2 "$BTFC" bsvtf "$W/l.btfc" -o "$W/bad.bsvtf"
expect_grep bsvtf-lpyr-msg "l.btfc: codec lpyr; BSVTF streams fmf models only" "$W/err.txt"
check convert-lpyr-bonn 2 "$BTFC" convert "$W/l.btfc" -o "$W/bad.btf"
expect_grep convert-lpyr-msg "l.btfc: codec lpyr; a Bonn .btf holds fmf models only" "$W/err.txt"
[ ! -e "$W/bad.bsvtf" ] && [ ! -e "$W/bad.btf" ] && echo "ok   other-codecs-no-output" || { echo "FAIL other-codecs-no-output"; fails=$((fails + 1)); }
check bsvtf-quiet 0 "$BTFC" -q bsvtf "$W/m.btfc" -o "$W/q.bsvtf" --tile 8
[ ! -s "$W/out.txt" ] && echo "ok   bsvtf-quiet-silent" || { echo "FAIL bsvtf-quiet-silent"; cat "$W/out.txt"; fails=$((fails + 1)); }
check tilecache-not-bsvtf 2 "$BTFC" tilecache "$W/m.btfc"
expect_grep tilecache-not-bsvtf-msg "wrong magic" "$W/err.txt"
# render
check render-flat 0 "$BTFC" render "$W/m.btfc" -o "$W/r.png" --light 30,45 --distance 2
check render-sphere 0 "$BTFC" render "$W/s.btfc" -o "$W/r.exr" --shape sphere --size 48
check render-below 1 "$BTFC" render "$W/m.btfc" -o "$W/r2.png" --view 120,0
[ ! -e "$W/r2.png" ] && echo "ok   render-no-output" || { echo "FAIL render-no-output"; fails=$((fails + 1)); }

# export (fmf here; other codecs' lines follow their exporters)
check export-fmf 0 "$BTFC" export "$W/m.btfc" --to "$W/exp-fmf"
for f in manifest.json btf.frag eigen_texture.ktx2 eigen_abrdf.ktx2 dir_index.ktx2 dir_weight.ktx2 model.bsvtf previews/eigen_texture.exr previews/dir_index.png; do
  [ -s "$W/exp-fmf/$f" ] || { echo "FAIL export-fmf-files: $f missing"; fails=$((fails + 1)); }
done
check export-json 0 "$BTFC" --json export "$W/m.btfc" --to "$W/exp-fmf2" --float --no-previews --no-bsvtf --direction-map 32
[ ! -e "$W/exp-fmf2/model.bsvtf" ] && echo "ok   export-no-bsvtf" || { echo "FAIL export-no-bsvtf"; fails=$((fails + 1)); }
expect_grep export-json-format '"format": "rgba32f"' "$W/out.txt"
check export-bsvtf-info 0 "$BTFC" tilecache "$W/exp-fmf/model.bsvtf" --cache-tiles 4 --frames 4
check export-not-empty 1 "$BTFC" export "$W/m.btfc" --to "$W/exp-fmf"
check export-raw 1 "$BTFC" export "$W/s.btfc" --to "$W/exp-raw"
[ ! -e "$W/exp-raw" ] && [ ! -e "$W/exp-raw.tmp-export" ] && echo "ok   export-no-output" || { echo "FAIL export-no-output"; fails=$((fails + 1)); }
# dfmf with the default offset (from the data): textures, shader and the BSVTF (colour model 13)
# carry it
check compress-dfmf-auto 0 "$BTFC" compress "$W/s.btfc" -c fmf:color=dfmf:rank=6:chroma_rank=2 -o "$W/dfa.btfc"
check export-dfmf-auto 0 "$BTFC" export "$W/dfa.btfc" --to "$W/exp-dfa" --no-previews
! grep -q "not written" "$W/err.txt" && echo "ok   export-dfmf-auto-no-warning" || { echo "FAIL export-dfmf-auto-no-warning"; cat "$W/err.txt"; fails=$((fails + 1)); }
expect_grep export-dfmf-auto-shader "const float DFMF_OFFSET" "$W/exp-dfa/btf.frag"
[ -s "$W/exp-dfa/eigen_texture.ktx2" ] && [ -s "$W/exp-dfa/model.bsvtf" ] && echo "ok   export-dfmf-auto-files" || { echo "FAIL export-dfmf-auto-files"; fails=$((fails + 1)); }
check bsvtf-dfmf-auto 0 "$BTFC" bsvtf "$W/dfa.btfc" -o "$W/dfa.bsvtf"
cmp -s "$W/dfa.bsvtf" "$W/exp-dfa/model.bsvtf" && echo "ok   bsvtf-dfmf-auto-same" || { echo "FAIL bsvtf-dfmf-auto-same"; fails=$((fails + 1)); }
check tilecache-dfmf-auto 0 "$BTFC" tilecache "$W/dfa.bsvtf" --cache-tiles 4 --frames 4
# The randomized dfmf encode converts the BTF compress read in place, once (Context::consumable):
# the input file is untouched and the model is as close to it as the exact encode's.
sum_before=$(sha256sum "$W/s.btfc" | cut -d' ' -f1)
check compress-dfmf-inplace 0 "$BTFC" compress "$W/s.btfc" -c fmf:color=dfmf:rank=6:chroma_rank=2:svd=randomized:power_iters=2 -o "$W/dfr.btfc"
[ "$(sha256sum "$W/s.btfc" | cut -d' ' -f1)" = "$sum_before" ] && echo "ok   compress-dfmf-inplace-input" || { echo "FAIL compress-dfmf-inplace-input"; fails=$((fails + 1)); }
check compare-dfmf-exact 0 "$BTFC" --json compare "$W/s.btfc" "$W/dfa.btfc"
cp "$W/out.txt" "$W/cmp-exact.json"
check compare-dfmf-inplace 0 "$BTFC" --json compare "$W/s.btfc" "$W/dfr.btfc"
python3 - "$W/cmp-exact.json" "$W/out.txt" <<'PY' || fails=$((fails + 1))
import json, sys
e, r = (json.load(open(p))["rel_l2"] for p in sys.argv[1:3])
assert e > 0 and abs(r - e) <= 0.02 * e, (e, r)  # half-float storage: either may be the lower
print("ok   compare-dfmf-inplace-values", e, r)
PY
cat >"$W/scene.json" <<'JSON'
{"materials": [{"name": "floor", "footprint": [2, 8], "view_cone": {"theta": 0, "phi": 0, "angle": 30}, "gpu_budget": "4M"}]}
JSON
check export-scene 0 "$BTFC" --json export "$W/m.btfc" --to "$W/exp-scene" --scene "$W/scene.json" --no-previews
expect_grep export-scene-report '"predicted_added_rel_error"' "$W/out.txt"
expect_grep export-scene-manifest '"mip_levels"' "$W/exp-scene/manifest.json"
echo '{"materials": [{"fooprint": [1, 2]}]}' >"$W/bad-scene.json"
check export-scene-bad 1 "$BTFC" export "$W/m.btfc" --to "$W/exp-scene2" --scene "$W/bad-scene.json"
expect_grep export-scene-bad-msg "unknown key 'fooprint'" "$W/err.txt"
check export-bad-magic 2 "$BTFC" export "$W/err.txt" --to "$W/exp-bad"
# GPU export: lpyr (seed 001 section 3.3 maps) and lpca with PRT maps under an environment (any EXR as lat-long)
check export-lpyr 0 "$BTFC" export "$W/l.btfc" --to "$W/exp-lpyr"
[ -f "$W/exp-lpyr/weight_map.ktx2" ] && [ -f "$W/exp-lpyr/direction_lut.ktx2" ] && grep -q "vec3 btf_eval_nearest_lod" "$W/exp-lpyr/btf.frag" && echo "ok   export-lpyr-files" || { echo "FAIL export-lpyr-files"; ls "$W/exp-lpyr"; fails=$((fails + 1)); }
check lpca-compress 0 "$BTFC" compress "$W/s.btfc" -c lpca:clusters=2:components=3 -o "$W/c.btfc"
check export-lpca-env 0 "$BTFC" --json export "$W/c.btfc" --to "$W/exp-lpca" --env "$W/r.exr" --sh-order 3
python3 -c "import json,sys; m=json.load(open(sys.argv[1])); n=[t['name'] for t in m['textures']]; assert 'prt' in n and 'eigen_sh' in n and len(m['evaluation']['prt_scale'])==2, n; print('ok   export-lpca-prt', n)" "$W/exp-lpca/manifest.json" || fails=$((fails + 1))
check export-lpyr-env 1 "$BTFC" export "$W/l.btfc" --to "$W/exp-bad" --env "$W/r.exr"
[ ! -e "$W/exp-bad" ] && echo "ok   export-no-output" || { echo "FAIL export-no-output"; fails=$((fails + 1)); }

echo "$fails failure(s)"
[ "$fails" -eq 0 ]
