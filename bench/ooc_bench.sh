#!/usr/bin/env bash
# Out-of-core and MPI benchmark of fmf (docs/scaling.md, docs/benchmarks.md):
# a synthetic 256 x 256 texel, 81 x 81 direction RGB BTF (5.2 GB float32) compressed
#   1. in core (btfc compress, enough --max-memory),
#   2. out of core with --max-memory 1G: the raw .btfc streamed in place (the default for raw
#      inputs), then with a working file (--work-file: built, then reused),
#   3. with btfc-mpi on 1 and 2 ranks (one thread per rank) from the working file, and from the
#      raw .btfc in place (each rank maps only its own chunks).
# Usage: bench/ooc_bench.sh [BUILD_DIR] [WORK_DIR]   (WORK_DIR needs ~8 GB; removed at the end)
set -euo pipefail
B=${1:-build}
W=${2:-$B/bench-ooc}
SPEC=${SPEC:-fmf:rank=32}
mkdir -p "$W"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
T="/usr/bin/time -f %e_s_%M_KB"
[ -f "$W/s256.btfc" ] || $T "$B/btfc" -q synth --width 256 --height 256 --seed 1 -o "$W/s256.btfc"
echo "== in core"
$T "$B/btfc" --json compress "$W/s256.btfc" -c $SPEC -o "$W/in.btfc" --max-memory 16G > "$W/in.json"
echo "== out of core, --max-memory 1G, raw .btfc streamed in place (no working file)"
$T "$B/btfc" --json compress "$W/s256.btfc" -c $SPEC -o "$W/raw.btfc" --max-memory 1G > "$W/raw.json"
rm -f "$W/w.btf"
echo "== out of core, --max-memory 1G (builds the working file)"
$T "$B/btfc" --json compress "$W/s256.btfc" -c $SPEC -o "$W/ooc.btfc" --max-memory 1G --work-file "$W/w.btf" > "$W/ooc.json"
echo "== out of core, working file reused"
$T "$B/btfc" --json compress "$W/s256.btfc" -c $SPEC -o "$W/ooc2.btfc" --max-memory 1G --work-file "$W/w.btf" > "$W/ooc2.json"
if [ -x "$B/btfc-mpi" ]; then
  for n in 1 2; do
    echo "== btfc-mpi, $n rank(s), one thread each, from the working file"
    # Each rank bound to its own core: "one thread per rank" means one core per rank; unbound,
    # a single rank's chunk-reader thread runs on the second core and the baseline uses ~1.7 cores.
    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 $T mpirun --bind-to core -n $n "$B/btfc-mpi" compress "$W/w.btf" \
      -c $SPEC -o "$W/mpi$n.btfc" --max-memory 1G --json > "$W/mpi$n.json"
  done
  for n in 1 2; do
    echo "== btfc-mpi, $n rank(s), one thread each, raw .btfc in place (each rank maps its own chunks)"
    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 $T mpirun --bind-to core -n $n "$B/btfc-mpi" compress "$W/s256.btfc" \
      -c $SPEC -o "$W/mpiraw$n.btfc" --max-memory 1G --json > "$W/mpiraw$n.json"
  done
fi
python3 - "$W" <<'PY'
import json, sys
w = sys.argv[1]
def load(n):
    try: return json.load(open(f"{w}/{n}.json"))
    except Exception: return None
i, o, o2, rw = load("in"), load("ooc"), load("ooc2"), load("raw")
print("in core:      read %.1f s + encode %.1f s, rel error %.5f" % (i["read_seconds"], i["encode_seconds"], i["stats"]["rel_error.rgb"]))
for name, r in (("ooc in place", rw), ("ooc build", o), ("ooc reuse", o2)):
    x = r["out_of_core"]
    print("%-12s encode %.1f s (work file %.1f s, factorization %.1f s), %d passes %s s, %.2f GB read, peak RSS %.2f GB, rel error %.5f" % (
        name, r["encode_seconds"], x["work_file_seconds"], x["factorize_seconds"], x["passes"],
        [round(p, 2) for p in x["pass_seconds"]], x["bytes_read"] / 1e9, x["peak_rss_bytes"] / 1e9, r["stats"]["rel_error.rgb"]))
for n, name in ((1, "mpi1"), (2, "mpi2"), (1, "mpiraw1"), (2, "mpiraw2")):
    r = load(name)
    if r:
        print("%-8s %d rank(s): factorization %.1f s, passes (rank 0) %s s, allreduce %.3f MB per rank, per rank %s" % (
            name, n, r["factorize_seconds"], [round(p, 2) for p in r["pass_seconds_rank0"]], r["allreduce_bytes_per_rank"] / 1e6,
            [(p["rank"], round(p["bytes_read"] / 1e9, 2), round(p["pass_seconds"], 1), round(p["reduce_seconds"], 2), round(p["peak_rss_bytes"] / 1e9, 2)) for p in r["per_rank"]]))
PY
[ "${KEEP:-0}" = 1 ] || rm -f "$W"/s256.btfc "$W"/w.btf "$W"/*.btfc
