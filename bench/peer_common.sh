# Shared by bench/peer_sklearn.sh and bench/peer_sklearn_dfmf.sh (sourced, after `set -euo
# pipefail`): their options, bench_fmf, a python3 with scikit-learn, and the same OpenBLAS kernels
# for both sides. Sets BUILD MATRIX WORKDIR RANKS REPEAT KEEP BTFC_FILE BENCH PY; defines cli_run and cli_line.
BUILD=build
MATRIX=""
WORKDIR=""
RANKS="16 32 64"
REPEAT=2
KEEP=0
BTFC_FILE=""
while [ $# -gt 0 ]; do
  case "$1" in
    --build) BUILD=$2; shift 2 ;;
    --matrix) MATRIX=$2; shift 2 ;;
    --workdir) WORKDIR=$2; shift 2 ;;
    --ranks) RANKS=$2; shift 2 ;;
    --repeat) REPEAT=$2; shift 2 ;;
    --keep) KEEP=1; shift ;;
    --btfc) BTFC_FILE=$2; shift 2 ;;
    *) echo "unknown argument $1" >&2; exit 1 ;;
  esac
done
BENCH="$BUILD/bench/bench_fmf"
WORKDIR=${WORKDIR:-$BUILD/peer-sklearn}  # inside the build folder (ignored by git)
[ -x "$BENCH" ] || { echo "no $BENCH (build first)" >&2; exit 1; }
# Debian's python3 (python3-sklearn, numpy on the system's OpenBLAS), or the first that imports sklearn.
PY=""
for p in /usr/bin/python3 $(command -v python3 || true); do
  if "$p" -c "import sklearn" 2>/dev/null; then PY=$p; break; fi
done
[ -n "$PY" ] || { echo "python3-sklearn missing: run scripts/setup.sh" >&2; exit 1; }
# The same OpenBLAS kernels for both: btfc re-executes itself with OPENBLAS_CORETYPE=SkylakeX on
# CPUs with AVX-512 (core/blas_env.h); numpy gets the same setting here.
if grep -q avx512vl /proc/cpuinfo && [ -z "${OPENBLAS_CORETYPE:-}" ]; then export OPENBLAS_CORETYPE=SkylakeX; fi

# cli_run WHO SPEC: the command-line encodes of the same BTF as a raw .btfc (--btfc FILE, written
# by `btfc synth --width 256 --height 256 --seed 1`, the material bench_fmf dumps), i.e. the
# out-of-core and MPI paths a user runs rather than bench_fmf's streamed SVD over memory: WHO ooc
# is `btfc compress FILE -c SPEC --max-memory 1G` (the raw .btfc streamed in place), WHO mpi is
# btfc-mpi on 2 ranks with one core each (each maps its own chunks). Prints "SECONDS PEAK_GB
# NAME=VALUE..." : the factorization's time (the streamed passes, color=dfmf's automatic offset
# included), the peak RSS (per rank for mpi) and the model's encode stats.
cli_run() {
  mkdir -p "$WORKDIR"
  local out="$WORKDIR/peer-cli.btfc" js="$WORKDIR/peer-cli.json" info="$WORKDIR/peer-cli-info.json"
  rm -f "$out"
  # The file read afresh into the page cache (dropped first): the state one sequential read leaves
  # (2 MB folios on this project's kernel), not the one the runs before leave, where memory
  # pressure evicted parts that the mappings then read back in small folios; on the project's VM
  # each pass pays ~1 us per freshly mapped 4 KiB page, so that state took 3 x as long
  # (docs/benchmarks.md, fmf section, seventh session of 2026-12-05).
  "$PY" -c "import os, sys; fd = os.open(sys.argv[1], os.O_RDONLY); os.posix_fadvise(fd, 0, 0, os.POSIX_FADV_DONTNEED)" "$BTFC_FILE"
  cat "$BTFC_FILE" > /dev/null
  if [ "$1" = ooc ]; then
    "$BUILD/btfc" --json compress "$BTFC_FILE" -c "$2" -o "$out" --max-memory 1G > "$js"
    echo '{}' > "$info"
  else
    OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 \
      mpirun --bind-to core -n 2 "$BUILD/btfc-mpi" compress "$BTFC_FILE" -c "$2" -o "$out" --max-memory 1G --json > "$js"
    "$BUILD/btfc" --json info "$out" > "$info"
  fi
  "$PY" - "$js" "$info" <<'PYEOF'
import json, re, sys
r, info = json.load(open(sys.argv[1])), json.load(open(sys.argv[2]))
if "out_of_core" in r:
    x = r["out_of_core"]
    secs, peak, stats = x["factorize_seconds"], x["peak_rss_bytes"], r["stats"]
else:
    secs, peak = r["factorize_seconds"], max(p["peak_rss_bytes"] for p in r["per_rank"])
    stats = dict(re.findall(r"^(\S+) = (\S+)$", info["encode_stats"], re.M))
print(f"{secs:.4f} {peak / 1e9:.4f} " + " ".join(f"{k}={v}" for k, v in stats.items()))
PYEOF
  rm -f "$out" "$js" "$info"
}

# cli_line WHO RANK Q P [dfmf]: cli_run's encode at that rank, power_iters and oversample (with
# color=dfmf when asked) as a line of the calling script's log: peer_sklearn.sh's "WHO rank R q Q
# p P krylov: T s, rel L2 error E, peak RSS X GB (Y x input)", or peer_sklearn_dfmf.sh's "WHO
# rank R q Q p P dfmf: T s, errors Ey Eu Ev, peak RSS Y x input".
cli_line() {
  local color="" r
  if [ "${5:-}" = dfmf ]; then color=":color=dfmf"; fi
  r=$(cli_run "$1" "fmf:rank=$2$color:power_iters=$3:oversample=$4")
  "$PY" - "$1" "$2" "$3" "$4" "${5:-rgb}" "$r" "$BTFC_FILE" <<'PYEOF'
import os, re, sys
who, rank, q, p, mode, r, path = sys.argv[1:8]
secs, peak = (float(x) for x in r.split()[:2])
inp = os.path.getsize(path) / 1e9  # the raw .btfc: its float tensor and a header of a few KB
err = lambda c: float(re.search(rf"rel_error\.{c}=([\d.eE+-]+)", r).group(1))
if mode == "dfmf":
    e = [err(c) for c in "yuv"]
    print(f"{who:10s} rank {rank} q {q} p {p} dfmf: {secs:.2f} s, errors {e[0]:.6f} {e[1]:.6f} {e[2]:.6f}, peak RSS {peak / inp:.2f} x input", flush=True)
else:
    print(f"{who:10s} rank {rank} q {q} p {p} krylov: {secs:.2f} s, rel L2 error {err('rgb'):.6f}, peak RSS {peak:.2f} GB ({peak / inp:.2f} x input)", flush=True)
PYEOF
}
