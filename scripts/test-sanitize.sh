#!/usr/bin/env bash
# Pass 3 of scripts/test.sh (issue 25, docs/robustness.md "Sanitizer pass"): builds btfc with
# AddressSanitizer + UndefinedBehaviorSanitizer (clang 14, -O1, libFuzzer's coverage
# instrumentation too, so the same tree serves the fuzz smoke) into build-san/, reused when warm,
# and runs the test suite under it:
#   - on the CPU path (BTFC_FORCE_CPU=1) with the leak checker on;
#   - the OpenCL tests (host code of the kernels) once more with OpenCL on PoCL;
#   - then each libFuzzer target for a fixed number of runs over its committed corpus
#     (scripts/fuzz.sh --runs).
# Under the sanitizers the code runs 3-8 times slower, and the whole suite takes about 40 minutes
# on 2 cores, so by default (test.sh, CI) the pass leaves out the measurements (SLOW below: quality,
# ratio and search figures on 48-64 texel crops and whole-CLI scenarios, whose code paths the kept
# tests reach on small inputs; docs/robustness.md lists them and their times) and keeps every test
# of input handling, every codec's contract, the CLI's error paths and the streaming, export and
# signal checks. `--all` runs everything (measured: docs/robustness.md).
# Any sanitizer report fails the pass, also from a process whose non-zero exit a test expects
# (a CLI check of a bad file): every report goes to build-san/san-logs/ (log_path) and a
# non-empty folder is a failure. Third-party leaks only are suppressed, in tests/lsan.supp.
# Checks that cannot hold under a sanitizer (peak RSS: ASan's shadow memory and quarantine)
# skip themselves with a message when BTFC_SANITIZER=1.
#
#   scripts/test-sanitize.sh              # build, the pass, the fuzz smoke
#   scripts/test-sanitize.sh --all        # the whole suite (about 40 minutes on 2 cores)
#   scripts/test-sanitize.sh -R Golden    # extra arguments go to ctest (the fuzz smoke is skipped)
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
ALL=0
if [ "${1:-}" = --all ]; then ALL=1; shift; fi
# Left out unless --all (ctest regex; each >= 8 s under the sanitizers on 2 cores):
SLOW=(
  # search and sweep figures: many encodes of one crop (Target.*, Bench, FmfQuant, Lpca seeds)
  'Target\.(FmfByteBudget|SsimOnLpca|ByteBudgetProbes|PsnrChooses|ByteBudgetChooses|UnreachableTargets)'
  'Bench\.SameSpecSameData' 'FmfQuant\.(MoreBits|ModelSavesLoads|MaxBytesSearches)' 'Lpca\.(PrunedAssignment|DeterministicBySeed)'
  'Lpyr\.MaxBytesSearches' 'MlvqQuality\.Stricter' 'MlvqMeasured\.RatioFloor' 'Relight\.EveryCodecRelights' 'Render\.ModelRenders'
  # numerical accuracy of the SVD paths on large matrices (Eigen's and OpenBLAS's loops)
  'Svd\.(LargeGram|BlockKrylovIsWithin|BlockKrylovStops)' 'StreamingExact\.(MatchesTheInCore|ThreeProcesses)'
  'NoOpenCL\.AutoRuns'
  # whole-CLI scenarios on real or 56-texel data: the textile, the streamed encodes,
  # the README, the installed package, the browser, the Python module under an uninstrumented
  # interpreter
  'cli_roundtrip' 'bonn_dfmf_interop' 'stream_cli' 'readme' 'install_consumer' 'viewer_browser' 'python'
  # writes and reads a 6 561-image set through OpenImageIO (19 s, 336 s under the sanitizers);
  # the image-set code is in io_tests' ImageSet.* and fuzz_image_set
  'imageio_loading'
)
EXCLUDE=$(IFS='|'; echo "^(${SLOW[*]})")
# io_tests is one process: its textile quality measurements go the same way (the image-set
# reader's own tests stay).
IO_FILTER='-DefaultRatio.*:DefaultsTextile.*:DfmfHdr.*:LpTextile.*:MlvqTextile.*:QuantTextile.*'
if [ $ALL = 1 ]; then EXCLUDE='^$'; IO_FILTER='*'; fi
scripts/setup.sh
B=${BTFC_SAN_BUILD_DIR:-build-san}
LAUNCHER=()
if [ "${BTFC_CCACHE:-1}" != 0 ] && command -v ccache >/dev/null; then
  LAUNCHER=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache -DCMAKE_C_COMPILER_LAUNCHER=ccache)
  export CCACHE_BASEDIR=${CCACHE_BASEDIR:-$ROOT} CCACHE_NOHASHDIR=1
fi
t0=$(date +%s)
if [ ! -f "$B/CMakeCache.txt" ]; then
  # -O1 and line tables only: about half the compile time of -O2 -g, stack traces keep their
  # lines, and without NDEBUG Eigen's and the library's assertions are live checks too.
  CC=clang-14 CXX=clang++-14 cmake -S . -B "$B" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DBTFC_FUZZ=ON \
    -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -gline-tables-only" -DCMAKE_C_FLAGS_RELWITHDEBINFO="-O1 -gline-tables-only" \
    -DBTFC_BUILD_BENCH=OFF "${LAUNCHER[@]}" >/dev/null
fi
cmake --build "$B" -j "$(nproc)"
t1=$(date +%s)

LOGS=$(cd "$B" && pwd)/san-logs
rm -rf "$LOGS" && mkdir -p "$LOGS"
# exitcode 86: a sanitizer error is never mistaken for the exit 1 a bad-input check expects.
# intercept_tls_get_addr=0: up to LLVM 16 / GCC 13 the runtime's __tls_get_addr interceptor takes
# a dynamic TLS block that happens to start 16 bytes into a page for a pre-2.25 glibc header and
# reads garbage as a block address; at exit LeakSanitizer's tracer then dies of signal 11
# ("LeakSanitizer has encountered a fatal error", at random, more often next to PoCL's and
# OpenMP's threads). The cost: pointers held only in another library's dynamic TLS are not
# roots, which no btfc code relies on.
export ASAN_OPTIONS=detect_leaks=1:exitcode=86:log_path=$LOGS/asan:check_initialization_order=1:strict_string_checks=1:intercept_tls_get_addr=0:suppressions=$ROOT/tests/asan.supp
export LSAN_OPTIONS=suppressions=$ROOT/tests/lsan.supp:print_suppressions=0
export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1:exitcode=86:log_path=$LOGS/ubsan
export BTFC_SANITIZER=1
# OpenMPI keeps its plug-ins mapped at exit, so its leaks (tests/lsan.supp) have module names.
export OMPI_MCA_mca_base_component_disable_dlclose=1
reports() {
  if [ -n "$(ls -A "$LOGS")" ]; then
    echo "sanitizer reports ($LOGS):"
    for f in "$LOGS"/*; do echo "== $f"; head -40 "$f"; done
    return 1
  fi
}
status=0
cd "$B"
echo "== pass 3a: ASan + UBSan, CPU path (BTFC_FORCE_CPU=1), leak checker on$([ $ALL = 1 ] && echo ", the whole suite" || echo "; left out: $EXCLUDE")"
GTEST_FILTER=$IO_FILTER BTFC_FORCE_CPU=1 ctest --output-on-failure -j "$(nproc)" -E "$EXCLUDE" "$@" || status=1
t2=$(date +%s)
echo "== pass 3b: ASan + UBSan, the OpenCL tests on PoCL"
ctest --output-on-failure -j "$(nproc)" -R '^(OpenCL|OpenCLKernels|MlvqOpenCL)\.' "$@" || status=1
t3=$(date +%s)
cd "$ROOT"
reports || status=1
if [ $# -eq 0 ] && [ "${BTFC_FUZZ_SMOKE:-1}" != 0 ]; then
  echo "== fuzz smoke: every libFuzzer target, a fixed number of runs over its corpus"
  BTFC_FUZZ_BUILD_DIR=$B scripts/fuzz.sh --runs || status=1
fi
t4=$(date +%s)
echo "test-sanitize: build $((t1 - t0)) s, CPU pass $((t2 - t1)) s, OpenCL tests $((t3 - t2)) s, fuzz smoke $((t4 - t3)) s"
exit $status
