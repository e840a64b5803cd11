#!/usr/bin/env bash
# btfc's color=dfmf encode against scikit-learn's randomized_svd on the same three channel
# matrices, in one run (issue 24: "the same for color=dfmf"; results in docs/benchmarks.md, fmf
# section). The rgb comparison is bench/peer_sklearn.sh.
#
# The BTF is bench_fmf's synthetic UBO2003-size material (256 x 256 texels, 81 x 81 directions,
# seed 1). `bench_fmf --dump-dfmf` writes its three dfmf channel matrices (Y' = log luminance, U',
# V'; 6561 rows x 65536 texels, float32, 1.72 GB each) exactly as the encode forms them
# (automatic offset, dfmf_channel). For each repetition and each rank R (chroma rank R too):
#   btfc     bench_fmf --load RGB --codec fmf:rank=R:color=dfmf:power_iters=Q, Q = 4 (default) and 1: the
#            whole encode() call (offset, conversion, the three SVDs in one stream, quantisation,
#            the model), timed around the call in the process; per-channel errors from the
#            model's rel_error stats
#   sklearn  randomized_svd(n_components=R, n_oversamples=16, n_iter=Q) on each channel matrix,
#            Q = 4, 3 and 1 (LU normalizer), the three factorization times summed (loading and
#            the conversion are not timed: they favour scikit-learn)
#   and both with q 1 and p 8 and 4 (btfc `oversample=P`, scikit-learn n_oversamples=P, LU): block
#            Krylov keeps every block, so it needs less oversampling; both sides get the same grid
#   ooc, mpi with --btfc FILE (the same BTF as a raw .btfc: `btfc synth --width 256 --height 256
#            --seed 1 -o FILE`): the command line's out-of-core encode (`btfc compress FILE -c
#            fmf:rank=R:color=dfmf:power_iters=1:oversample=P --max-memory 1G`, the raw .btfc
#            streamed in place; p 16 and 8) and btfc-mpi's on 2 ranks of one core each (p 16 and 8):
#            the factorization's time with the automatic offset, peak RSS over the RGB input (per rank)
# Errors are sqrt(||B||^2 - sum s_i^2) / ||B|| per channel (orthogonal projections: exact). A
# run is at "equal error" when each of its three channel errors is within 1 % of the lowest any
# run reached on that channel; the summary gives the ratio of the fastest such btfc run to the
# fastest such scikit-learn run (goal <= 0.5) and each one's peak RSS over the input's size
# (btfc: the RGB BTF, 5.16 GB; scikit-learn: one channel matrix, the one it holds).
#
# Usage: bench/peer_sklearn_dfmf.sh [--build DIR] [--workdir DIR] [--matrix FILE] [--ranks "16 32 64"] [--repeat 2] [--keep]
#                                   [--btfc FILE]
#   The channel files go to WORKDIR (default BUILD/peer-sklearn; 5.2 GB) and are removed at the
#   end unless --keep (an existing set is reused), and so does the RGB matrix btfc reads (5.2 GB,
#   WORKDIR/ubo2003.f32), unless --matrix names an existing `bench_fmf --dump` of the same BTF
#   (as bench/peer_sklearn.sh takes; not removed). Needs python3-sklearn (scripts/setup.sh).
set -euo pipefail
. "$(dirname "$0")/peer_common.sh"
mkdir -p "$WORKDIR"
PREFIX="$WORKDIR/dfmf"
DUMPED=0
RGB_DUMPED=0
if [ -z "$MATRIX" ]; then MATRIX="$WORKDIR/ubo2003.f32"; fi
if [ ! -f "$PREFIX.v.f32" ] || [ ! -f "$MATRIX" ]; then
  # One synthesis for both: the RGB matrix (btfc's input, read back by every btfc run instead of
  # synthesizing it again: 8-49 s a run) and the channel matrices.
  if [ -f "$MATRIX" ]; then
    "$BENCH" --dump-dfmf "$PREFIX" --dump-only >&2
  else
    "$BENCH" --dump "$MATRIX" --dump-dfmf "$PREFIX" --dump-only >&2
    RGB_DUMPED=1
  fi
  DUMPED=1
fi
cleanup() {
  if [ "$DUMPED" = 1 ] && [ "$KEEP" = 0 ]; then rm -f "$PREFIX".[yuv].f32; fi
  if [ "$RGB_DUMPED" = 1 ] && [ "$KEEP" = 0 ]; then rm -f "$MATRIX"; fi
}
trap cleanup EXIT

# "sklearn rank R q Q NORM: T s, errors Ey Eu Ev, peak RSS X x input"
sk() {
  "$PY" - "$PREFIX" 6561 "$1" "$2" "${4:-16}" "${3:-auto}" <<'EOF'
import resource, sys, time
import numpy as np
from sklearn.utils.extmath import randomized_svd
prefix, m, rank, q, p, norm = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5]), sys.argv[6]
secs, errs, inp = 0.0, [], 0.0
for ch in "yuv":
    A = np.fromfile(f"{prefix}.{ch}.f32", dtype=np.float32).reshape(-1, m)  # texels x rows: B^T
    inp = A.size * 4 / 1e9
    total = 0.0
    for i in range(0, A.shape[0], 4096):
        blk = A[i:i + 4096].astype(np.float64)
        total += float(np.einsum("ij,ij->", blk, blk))
    del blk
    t = time.perf_counter()
    U, s, Vt = randomized_svd(A, n_components=rank, n_oversamples=p, n_iter=q, power_iteration_normalizer=norm, random_state=1)
    secs += time.perf_counter() - t
    errs.append(np.sqrt(max(0.0, total - float(np.sum(s.astype(np.float64) ** 2))) / total))
    del A, U, Vt
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 / 1e9
print(f"sklearn    rank {rank} q {q} p {p} {norm}: {secs:.2f} s, errors {errs[0]:.6f} {errs[1]:.6f} {errs[2]:.6f}, peak RSS {peak / inp:.2f} x input", flush=True)
EOF
}
bt() {
  local out
  local p=${3:-16}
  out=$("$BENCH" --load "$MATRIX" --codec "fmf:rank=$1:color=dfmf:power_iters=$2:oversample=$p")
  "$PY" - "$1" "$2" <<EOF
import re
out = """$out"""
st = dict(re.findall(r"^\s+(\S+) = (\S+)$", out, re.M))
enc = float(re.search(r"encode ([\d.]+) s", out).group(1))  # bench_fmf's timer around encode()
mem = float(re.search(r"\(([\d.]+) x input\)", out).group(1))
print(f"btfc       rank $1 q $2 p $p dfmf: {enc:.2f} s, errors {float(st['rel_error.y']):.6f} {float(st['rel_error.u']):.6f} {float(st['rel_error.v']):.6f}, peak RSS {mem:.2f} x input"
      f"  (Krylov blocks {st['krylov_blocks.y']} {st['krylov_blocks.u']} {st['krylov_blocks.v']})", flush=True)
EOF
}

cl() { cli_line "$@" dfmf; }
echo "# peer_sklearn_dfmf.sh: $(date -u +%FT%TZ), $(nproc) cores, load $(cut -d' ' -f1-3 /proc/loadavg), OPENBLAS_CORETYPE=${OPENBLAS_CORETYPE:-default}"
echo "# sklearn $("$PY" -c 'import sklearn; print(sklearn.__version__)'), numpy $("$PY" -c 'import numpy; print(numpy.__version__)'), channels $PREFIX.[yuv].f32"
LOG=$(mktemp)
for rep in $(seq 1 "$REPEAT"); do
  for r in $RANKS; do
    echo "## repetition $rep, rank $r"
    bt "$r" 4 | tee -a "$LOG"
    bt "$r" 1 | tee -a "$LOG"
    sk "$r" 4 | tee -a "$LOG"
    sk "$r" 3 | tee -a "$LOG"
    sk "$r" 1 LU | tee -a "$LOG"
    for p in 8 4; do
      bt "$r" 1 $p | tee -a "$LOG"
      sk "$r" 1 LU $p | tee -a "$LOG"
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
echo "## summary (medians over the repetitions); equal error = every channel within 1 % of its lowest error at that rank"
"$PY" - "$LOG" <<'EOF'
import re, statistics, sys
runs = {}
pat = r"(\w+)\s+rank (\d+) q (\d+) p (\d+) (\w+): ([\d.]+) s, errors ([\d.]+) ([\d.]+) ([\d.]+), peak RSS ([\d.]+) x input"
for line in open(sys.argv[1]):
    m = re.match(pat, line)
    if m:
        who, rank, q, p, variant, secs, ey, eu, ev, mem = m.groups()
        runs.setdefault((int(rank), who, variant, int(q), int(p)), []).append((float(secs), (float(ey), float(eu), float(ev)), float(mem)))
for rank in sorted({k[0] for k in runs}):
    rows = [(k, statistics.median(x[0] for x in v), tuple(statistics.median(x[1][c] for x in v) for c in range(3)), max(x[2] for x in v))
            for k, v in runs.items() if k[0] == rank]
    best = tuple(min(r[2][c] for r in rows) for c in range(3))
    print(f"rank {rank}: lowest errors y {best[0]:.6f} u {best[1]:.6f} v {best[2]:.6f}")
    for k, t, e, mem in sorted(rows, key=lambda r: (r[0][1], -r[0][3])):
        worst = max(e[c] / best[c] for c in range(3))
        print(f"  {k[1]:8s} {k[2]:5s} q {k[3]} p {k[4]}: {t:7.2f} s  errors {e[0]:.6f} {e[1]:.6f} {e[2]:.6f} (worst channel {worst:.4f} x lowest)  peak {mem:.2f} x input")
    ok = [r for r in rows if all(r[2][c] <= 1.01 * best[c] for c in range(3))]
    s = [r for r in ok if r[0][1] == "sklearn"]
    for who, name in (("btfc", "btfc"), ("ooc", "btfc out of core (CLI)"), ("mpi", "btfc-mpi 2 ranks")):
        b = [r for r in ok if r[0][1] == who]
        if b and s:
            fb, fs = min(b, key=lambda r: r[1]), min(s, key=lambda r: r[1])
            print(f"  equal error: {name} q {fb[0][3]} p {fb[0][4]} {fb[1]:.2f} s vs sklearn q {fs[0][3]} p {fs[0][4]} {fs[0][2]} {fs[1]:.2f} s -> ratio {fb[1] / fs[1]:.2f} (goal <= 0.5)")
EOF
rm -f "$LOG"
