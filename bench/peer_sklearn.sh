#!/usr/bin/env bash
# btfc's fmf factorization against its peer, scikit-learn's randomized_svd (numpy + OpenBLAS), on
# the same matrix in one run (issue 24; results in docs/benchmarks.md, fmf section).
#
# The matrix is the UBO2003 size: 19683 rows (81 x 81 directions x RGB) x 65536 texels, float32,
# 5.16 GB, written once by `bench_fmf --dump` (the `btfc synth` material, seed 1) unless a file is
# given. For each repetition and each rank, back to back (the machine is shared, so only ratios
# measured side by side mean much):
#   btfc     bench_fmf --load: truncated_svd, randomized, default scheme (block Krylov), q 4, p 16
#            (the codec's defaults: at most 5 blocks, stops once a block gains < 0.2 %)
#   sklearn  randomized_svd(n_components=rank, n_oversamples=16, n_iter=4): same q and p
#   sklearn  the same with n_iter=3
#   btfc     block Krylov q 1 p 16: 2 blocks, 4 passes
#   sklearn  n_iter=1, power_iteration_normalizer="LU": also 4 passes (its default for n_iter <= 2
#            is no normalisation, which loses the small components in float32 from n_iter 2 on)
#   streamed bench_fmf --streamed 0: the out-of-core SVD (codecs/fmf/ooc_svd.h, the passes the
#            out-of-core and MPI paths run) over the same matrix in the CLI's largest chunks,
#            mapped from memory as a raw .btfc is from the page cache: q 4 and q 1, p 16
#   and q 1 with p 8 and p 4 for all three (btfc `fmf:power_iters=1:oversample=8`, scikit-learn
#            n_iter=1, n_oversamples=8, LU): block Krylov keeps every block, so its basis has
#            2 (k + p) columns after one iteration and needs less oversampling (Musco and Musco
#            2015 take none); scikit-learn keeps only the last block. Both sides get the same
#            grid of (q, p), so neither is compared at settings only the other was given. (How
#            little is enough depends on the spectrum: on tests/svd_test.cpp's harmonic-decay
#            matrix, q 1 at rank 32 needs p 16 to stay within 1 %, q 2 needs none.)
#   ooc      with --btfc FILE (the same BTF as a raw .btfc: `btfc synth --width 256 --height 256
#            --seed 1 -o FILE`): the command line's out-of-core encode, `btfc compress FILE -c
#            fmf:rank=R:power_iters=1:oversample=P --max-memory 1G` (the raw .btfc streamed in place
#            from the page cache, its chunks mapped and unmapped in every pass), p 16 and 8
#   mpi      with --btfc, where btfc-mpi was built: the same on 2 MPI ranks of one core each, p 16 and 8
#            (time: the factorization in the JSON; peak RSS: per rank)
# Each run is its own process: time of the factorization only (not the load), relative L2 error
# sqrt(||B||^2 - sum s_i^2) / ||B|| (both approximations are orthogonal projections of B, so this
# is their exact error), peak RSS (getrusage) over the input's size. Then, per rank, the ratio of
# the fastest btfc run's time to the fastest scikit-learn run's, both within 1 % of the lowest
# error any run reached at that rank ("equal error").
#
# Usage: bench/peer_sklearn.sh [--build DIR] [--matrix FILE] [--workdir DIR] [--ranks "16 32 64"]
#                              [--repeat 2] [--keep] [--btfc FILE]
#   --matrix: an existing dump (not removed); else the dump goes to WORKDIR/ubo2003.f32 (default
#   BUILD/peer-sklearn; needs 5.2 GB) and is removed at the end unless --keep.
# Needs python3-sklearn (scripts/setup.sh installs it).
set -euo pipefail
. "$(dirname "$0")/peer_common.sh"
ROWS=19683
DUMPED=0
if [ -z "$MATRIX" ]; then
  mkdir -p "$WORKDIR"
  MATRIX="$WORKDIR/ubo2003.f32"
  if [ ! -f "$MATRIX" ]; then
    "$BENCH" --dump "$MATRIX" --dump-only >&2
    DUMPED=1
  fi
fi
cleanup() { if [ "$DUMPED" = 1 ] && [ "$KEEP" = 0 ]; then rm -f "$MATRIX"; fi; }
trap cleanup EXIT

# One scikit-learn run: "sklearn rank R q Q p P NORM: T s, rel L2 error E, peak RSS X GB (Y x input)".
sk() {
  "$PY" - "$MATRIX" "$ROWS" "$1" "$2" "$3" "${4:-auto}" <<'EOF'
import resource, sys, time
import numpy as np
from sklearn.utils.extmath import randomized_svd
path, m, rank, q, p, norm = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5]), sys.argv[6]
A = np.fromfile(path, dtype=np.float32)
A = A.reshape(-1, m)  # row-major texels x rows: the transpose of btfc's column-major B, same values
total = 0.0
for i in range(0, A.shape[0], 4096):
    blk = A[i:i + 4096].astype(np.float64)
    total += float(np.einsum("ij,ij->", blk, blk))
del blk
t = time.perf_counter()
U, s, Vt = randomized_svd(A, n_components=rank, n_oversamples=p, n_iter=q, power_iteration_normalizer=norm, random_state=1)
secs = time.perf_counter() - t
err = np.sqrt(max(0.0, total - float(np.sum(s.astype(np.float64) ** 2))) / total)
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 / 1e9
inp = A.size * 4 / 1e9
print(f"sklearn    rank {rank} q {q} p {p} {norm}: {secs:.2f} s, rel L2 error {err:.6f}, peak RSS {peak:.2f} GB ({peak / inp:.2f} x input)", flush=True)
EOF
}
bt() { "$BENCH" --load "$MATRIX" --rows "$ROWS" --svd-only --rank "$1" --power-iters "$2" --oversample "$3" --scheme "$4" | grep '^fmf'; }
cl() { cli_line "$@"; }
st() { "$BENCH" --load "$MATRIX" --rows "$ROWS" --rank "$1" --power-iters "$2" --oversample "$3" --streamed 0 | grep '^streamed'; }

echo "# peer_sklearn.sh: $(date -u +%FT%TZ), $(nproc) cores, load $(cut -d' ' -f1-3 /proc/loadavg), OPENBLAS_CORETYPE=${OPENBLAS_CORETYPE:-default}"
echo "# sklearn $("$PY" -c 'import sklearn; print(sklearn.__version__)'), numpy $("$PY" -c 'import numpy; print(numpy.__version__)'), matrix $MATRIX"
LOG=$(mktemp)
for rep in $(seq 1 "$REPEAT"); do
  for r in $RANKS; do
    echo "## repetition $rep, rank $r"
    bt "$r" 4 16 krylov | tee -a "$LOG"
    sk "$r" 4 16 | tee -a "$LOG"
    sk "$r" 3 16 | tee -a "$LOG"
    bt "$r" 1 16 krylov | tee -a "$LOG"
    sk "$r" 1 16 LU | tee -a "$LOG"
    st "$r" 4 16 | tee -a "$LOG"
    st "$r" 1 16 | tee -a "$LOG"
    for p in 8 4; do
      bt "$r" 1 $p krylov | tee -a "$LOG"
      sk "$r" 1 $p LU | tee -a "$LOG"
      st "$r" 1 $p | tee -a "$LOG"
    done
    if [ -n "$BTFC_FILE" ]; then
      cl ooc "$r" 1 16 | tee -a "$LOG"
      cl ooc "$r" 1 8 | tee -a "$LOG"
      if [ -x "$BUILD/btfc-mpi" ] && command -v mpirun > /dev/null; then
        cl mpi "$r" 1 16 | tee -a "$LOG"
        cl mpi "$r" 1 8 | tee -a "$LOG"
      fi
    fi
  done
done
echo "## summary (medians over the repetitions); equal error = within 1 % of the lowest error at that rank"
"$PY" - "$LOG" <<'EOF'
import re, statistics, sys
runs = {}
pat = r"(\w+)\s+rank (\d+) q (\d+) p (\d+) (\w+): ([\d.]+) s, rel L2 error ([\d.]+).*?\(([\d.]+) x input\)"
for line in open(sys.argv[1]):
    m = re.match(pat, line)
    if m:
        who, rank, q, p, variant, secs, err, mem = m.groups()
        runs.setdefault((int(rank), who, variant, int(q), int(p)), []).append((float(secs), float(err), float(mem)))
for rank in sorted({k[0] for k in runs}):
    rows = [(k, statistics.median(x[0] for x in v), statistics.median(x[1] for x in v), max(x[2] for x in v))
            for k, v in runs.items() if k[0] == rank]
    best = min(r[2] for r in rows)
    print(f"rank {rank}: lowest error {best:.6f}")
    for k, t, e, mem in sorted(rows, key=lambda r: (r[0][1], -r[0][3])):
        print(f"  {k[1]:8s} {k[2]:6s} q {k[3]} p {k[4]}: {t:7.2f} s  err {e:.6f} ({e / best:.4f} x lowest)  peak {mem:.2f} x input")
    ok = [r for r in rows if r[2] <= 1.01 * best]
    s = [r for r in ok if r[0][1] == "sklearn"]
    for who, name in (("fmf", "btfc"), ("streamed", "btfc streamed"), ("ooc", "btfc out of core (CLI)"), ("mpi", "btfc-mpi 2 ranks")):
        b = [r for r in ok if r[0][1] == who]
        if b and s:
            fb, fs = min(b, key=lambda r: r[1]), min(s, key=lambda r: r[1])
            print(f"  equal error: {name} {fb[0][2]} q {fb[0][3]} p {fb[0][4]} {fb[1]:.2f} s vs sklearn q {fs[0][3]} p {fs[0][4]} {fs[0][2]} {fs[1]:.2f} s"
                  f" -> ratio {fb[1] / fs[1]:.2f} (goal <= 0.5)")
EOF
rm -f "$LOG"
