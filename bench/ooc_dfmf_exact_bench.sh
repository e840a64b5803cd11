#!/usr/bin/env bash
# Streamed color=dfmf and svd=exact against in core (docs/scaling.md "dfmf and exact out of core"):
#   1. btfc synth --width 64 --height 64 (81 x 81 directions, 322 MB float32), fmf:color=dfmf
#      (randomized, rank 32, chroma_rank 16) in core and with --max-memory 100M;
#   2. btfc synth --width 512 --height 512 --views 30,0 (81 lights x 1 view: 243 rows, 262144
#      texels, 255 MB), fmf:svd=exact in core and with --max-memory 64M (dfmf: 128M, its three
#      blocks of factors take 67 MB).
# Prints passes, factorization and wall time, peak RSS and rel. L2 per run, all in one run so
# the ratios are comparable on a shared machine. Usage: bench/ooc_dfmf_exact_bench.sh [BUILD_DIR] [WORK_DIR]
set -euo pipefail
B=${1:-build}
W=${2:-$B/bench-ooc-dfmf}
mkdir -p "$W"
[ -f "$W/s64.btfc" ] || "$B/btfc" -q synth --width 64 --height 64 --seed 1 -o "$W/s64.btfc"
[ -f "$W/v512.btfc" ] || "$B/btfc" -q synth --width 512 --height 512 --views 30,0 --seed 1 -o "$W/v512.btfc"
run() { # run NAME INPUT SPEC LIMIT
  local t0=$(date +%s.%N)
  /usr/bin/time -f %M -o "$W/$1.rss" "$B/btfc" --json compress "$2" -c "$3" -o "$W/$1.btfc" --max-memory "$4" > "$W/$1.json"
  local t1=$(date +%s.%N)
  "$B/btfc" --json compare --no-ssim "$2" "$W/$1.btfc" > "$W/$1.cmp.json"
  python3 - "$W/$1.json" "$W/$1.cmp.json" "$1" "$(echo "$t1 - $t0" | bc)" "$4" "$(cat "$W/$1.rss")" <<'PY'
import json, sys
r = json.load(open(sys.argv[1])); c = json.load(open(sys.argv[2])); o = r.get("out_of_core")
st = r.get("stats", {}); rss = int(sys.argv[6]) / 1024
if o:
    print("%-10s limit %-4s passes %2d  factorize %6.2f s  wall %6.2f s  peak RSS %6.1f MiB  rel_l2 %.7f  (%s)" % (
        sys.argv[3], sys.argv[5], o["passes"], o["factorize_seconds"], float(sys.argv[4]), rss, c["rel_l2"], st.get("svd.rgb", st.get("svd.y"))))
else:
    print("%-10s in core              encode    %6.2f s  wall %6.2f s  peak RSS %6.1f MiB  rel_l2 %.7f  (%s)" % (
        sys.argv[3], r["encode_seconds"], float(sys.argv[4]), rss, c["rel_l2"], st.get("svd.rgb", st.get("svd.y"))))
PY
}
D=fmf:color=dfmf:rank=32:chroma_rank=16:svd=randomized
run dfmf-in "$W/s64.btfc" $D 16G
run dfmf-ooc "$W/s64.btfc" $D 100M
run exact-in "$W/v512.btfc" fmf:rank=32:svd=exact 16G
run exact-ooc "$W/v512.btfc" fmf:rank=32:svd=exact 64M
run dexact-in "$W/v512.btfc" fmf:color=dfmf:rank=32:chroma_rank=16:svd=exact 16G
run dexact-ooc "$W/v512.btfc" fmf:color=dfmf:rank=32:chroma_rank=16:svd=exact 128M
rm -rf "$W"
