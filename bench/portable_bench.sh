#!/usr/bin/env bash
# Portable (default, BTFC_NATIVE=OFF) against native (-DBTFC_NATIVE=ON) builds of btfc, in one
# run on one machine (issue 23; docs/benchmarks.md "Portable and native builds").
#
# Each build runs the same work, alternating portable / native REPS times so that a slow spell of
# the machine hits both: `btfc bench` on DATA with one setting per codec (encode, decode and
# random-evaluation rate on the CPU path: --device cpu, because the OpenCL kernels are compiled
# by PoCL at run time and do not depend on btfc's build flags), then `btfc compare` (RMSE, PSNR,
# SSIM) and `btfc render` of the fmf model. Prints, per measured figure, the best of the REPS runs
# of each build and the ratio portable / native for times (native / portable for rates), so
# > 1 means the portable build is slower.
#
# Usage: bench/portable_bench.sh PORTABLE_BUILD NATIVE_BUILD [DATA] [REPS]
#   e.g. cmake -S . -B build-native -DCMAKE_BUILD_TYPE=Release -DBTFC_NATIVE=ON && cmake --build build-native
#        bench/portable_bench.sh build build-native ../shared/data/textile_lurex_utia64 2
set -euo pipefail
P=${1:?portable build dir}
N=${2:?native build dir}
DATA=${3:-../shared/data/textile_lurex_utia64}
REPS=${4:-2}
SPECS=(-c "${FMF_SPEC:-fmf:rank=16}" -c "${LPYR_SPEC:-lpyr:y=4}" -c "${LPCA_SPEC:-lpca:clusters=8:components=4}" -c "${MLVQ_SPEC:-mlvq}")
W=$(mktemp -d "${TMPDIR:-/tmp}/btfc-portable.XXXXXX")
trap 'rm -rf "$W"' EXIT
for b in "$P" "$N"; do
  [ -x "$b/btfc" ] || { echo "portable_bench: $b/btfc not found (build it first)" >&2; exit 2; }
done
echo "machine: $("$P/btfc" --version 2>/dev/null | head -1); $(nproc) cores; $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2-)"
grep -h -m1 BTFC_NATIVE "$P/CMakeCache.txt" "$N/CMakeCache.txt" | sed 's/^/  /'

# one KIND BUILD REP: appends "kind<TAB>figure<TAB>value" lines to $W/results
one() {
  local kind=$1 b=$2 rep=$3
  local out=$W/$kind.$rep
  mkdir -p "$out"
  "$b/btfc" --device cpu --json bench "$DATA" "${SPECS[@]}" --no-renders > "$out/bench.json"
  python3 - "$kind" "$out/bench.json" >> "$W/results" <<'EOF'
import json, sys
kind, path = sys.argv[1], sys.argv[2]
rows = json.load(open(path))["runs"]
for r in rows:
    s = r["spec"].split(":")[0]
    print(f"{kind}\t{s} encode s\t{r['encode_seconds']}")
    print(f"{kind}\t{s} decode s\t{r['decode_seconds']}")
    print(f"{kind}\t{s} M evals/s\t{r['evals_per_second'] / 1e6}")
EOF
  "$b/btfc" -q compress "$DATA" -c "${FMF_SPEC:-fmf:rank=16}" -o "$out/f.btfc" --device cpu
  local t0 t1
  t0=$(date +%s.%N)
  "$b/btfc" -q --device cpu compare "$DATA" "$out/f.btfc" > /dev/null
  t1=$(date +%s.%N)
  printf '%s\tcompare (SSIM) s\t%s\n' "$kind" "$(echo "$t1 - $t0" | bc)" >> "$W/results"
  t0=$(date +%s.%N)
  "$b/btfc" -q --device cpu render "$out/f.btfc" --shape sphere --size 512 -o "$out/r.exr" > /dev/null
  t1=$(date +%s.%N)
  printf '%s\trender sphere 512 s\t%s\n' "$kind" "$(echo "$t1 - $t0" | bc)" >> "$W/results"
}

for rep in $(seq 1 "$REPS"); do
  echo "run $rep of $REPS: portable" >&2
  one portable "$P" "$rep"
  echo "run $rep of $REPS: native" >&2
  one native "$N" "$rep"
done

python3 - "$W/results" <<'EOF'
import sys, collections
best = collections.defaultdict(dict)
order = []
for line in open(sys.argv[1]):
    kind, fig, v = line.rstrip("\n").split("\t")
    v = float(v)
    if fig not in order: order.append(fig)
    rate = "evals/s" in fig
    cur = best[fig].get(kind)
    best[fig][kind] = v if cur is None else (max(cur, v) if rate else min(cur, v))
print(f"| figure (best of runs) | portable | native | portable cost |")
print(f"|---|---|---|---|")
for fig in order:
    p, n = best[fig]["portable"], best[fig]["native"]
    cost = (n / p) if "evals/s" in fig else (p / n)
    print(f"| {fig} | {p:.3f} | {n:.3f} | {cost:.2f} x |")
EOF
