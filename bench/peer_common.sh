# Shared by bench/peer_sklearn.sh and bench/peer_sklearn_dfmf.sh (sourced, after `set -euo
# pipefail`): their options, bench_fmf, a python3 with scikit-learn, and the same OpenBLAS kernels
# for both sides. Sets BUILD MATRIX WORKDIR RANKS REPEAT KEEP BENCH PY.
BUILD=build
MATRIX=""
WORKDIR=""
RANKS="16 32 64"
REPEAT=2
KEEP=0
while [ $# -gt 0 ]; do
  case "$1" in
    --build) BUILD=$2; shift 2 ;;
    --matrix) MATRIX=$2; shift 2 ;;
    --workdir) WORKDIR=$2; shift 2 ;;
    --ranks) RANKS=$2; shift 2 ;;
    --repeat) REPEAT=$2; shift 2 ;;
    --keep) KEEP=1; shift ;;
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
