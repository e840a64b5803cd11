#!/usr/bin/env bash
# Builds the libFuzzer targets (tests/fuzz/, BTFC_FUZZ=ON, clang + ASan + UBSan) into build-fuzz/
# and runs each for SECONDS (default 60), one after another, niced, on one thread. A benchmark-
# style script, not part of CI. Prints per target: executions, exec/s, corpus size (files and
# coverage features) and findings (crash-*, leak-*, oom-*, timeout-* artifacts), and writes the
# table to BUILD/fuzz-report.txt. Exit status 1 when any target found something.
#
# Usage: scripts/fuzz.sh [SECONDS] [TARGET...]      e.g. scripts/fuzz.sh 600
#        scripts/fuzz.sh --runs [N] [TARGET...]      smoke: a fixed number of executions
# Targets: every line of tests/fuzz/targets.txt (the one list; CMake reads it too).
# Smoke mode (--runs) runs each target for N executions (libFuzzer -runs=N; without N, the
# target's smoke=N from targets.txt, chosen so that all targets take about a minute here) over
# its committed corpus and the golden seeds, with a scratch corpus in BUILD/smoke/<target> that
# is emptied first: nothing is added to tests/fuzz/corpus/ or to BUILD/corpus/. The smoke's
# mutations come from a fixed seed (libFuzzer -seed=1, or $BTFC_FUZZ_SEED), so that it is the
# same on every machine; timed runs draw a new seed each time.
# BUILD is $BTFC_FUZZ_BUILD_DIR (default build-fuzz). A missing BUILD is configured for fuzzing;
# an existing one is used as it is (never reconfigured; it must have -DBTFC_FUZZ=ON, e.g. a
# sanitizer build with tests), and the targets are built there if needed.
# A finding is reproduced with: BUILD/tests/fuzz/<target> BUILD/artifacts/<target>/crash-...
set -euo pipefail
cd "$(dirname "$0")/.."
TARGET_LIST=tests/fuzz/targets.txt
RUNS=""
SECONDS_PER=60
if [ "${1:-}" = --runs ]; then
  shift
  RUNS=default
  if [[ "${1:-}" =~ ^[0-9]+$ ]]; then RUNS=$1; shift; fi
elif [[ "${1:-}" =~ ^[0-9]+$ ]]; then
  SECONDS_PER=$1
  shift
fi
TARGETS=("$@")
[ ${#TARGETS[@]} -eq 0 ] && mapfile -t TARGETS < <(awk '/^[a-z]/ {print $1}' "$TARGET_LIST")
for t in "${TARGETS[@]}"; do
  awk '/^[a-z]/ {print $1}' "$TARGET_LIST" | grep -qx "$t" || { echo "fuzz.sh: unknown target '$t' (see $TARGET_LIST)" >&2; exit 2; }
done
# The smoke runs of a target: N, or its smoke=N in targets.txt (1000 when it has none).
smoke_runs() {
  if [ "$RUNS" != default ]; then echo "$RUNS"; return; fi
  local n
  n=$(awk -v t="$1" '$1 == t { for (i = 2; i <= NF; ++i) if ($i ~ /^smoke=/) { sub(/^smoke=/, "", $i); print $i } }' "$TARGET_LIST")
  echo "${n:-1000}"
}
# The target's own libFuzzer options in targets.txt (words starting with '-').
target_opts() {
  awk -v t="$1" '$1 == t { for (i = 2; i <= NF; ++i) if ($i ~ /^-/) print $i }' "$TARGET_LIST"
}

scripts/setup.sh
# Fuzz-only packages: clang with libFuzzer and the sanitizer runtimes, and clang's OpenMP.
FUZZ_PACKAGES=(clang-14 libclang-rt-14-dev libomp-14-dev)
missing=()
for p in "${FUZZ_PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  SUDO=""
  [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

B=${BTFC_FUZZ_BUILD_DIR:-build-fuzz}
if [ ! -f "$B/CMakeCache.txt" ]; then
  # -O1 and line tables only: half the compile time of -O2 -g on this 2-core machine, and
  # without NDEBUG, so Eigen's and the library's assertions are live checks while fuzzing.
  CC=clang-14 CXX=clang++-14 cmake -S . -B "$B" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DBTFC_FUZZ=ON \
    -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -gline-tables-only" -DCMAKE_C_FLAGS_RELWITHDEBINFO="-O1 -gline-tables-only" \
    -DBTFC_BUILD_TESTS=OFF -DBTFC_BUILD_BENCH=OFF >/dev/null
fi
if ! grep -q '^BTFC_FUZZ:BOOL=ON' "$B/CMakeCache.txt"; then
  echo "fuzz.sh: $B is not configured with -DBTFC_FUZZ=ON (set BTFC_FUZZ_BUILD_DIR to a fuzz build, or remove $B)" >&2
  exit 2
fi
nice -n 10 cmake --build "$B" -j 2 --target "${TARGETS[@]}"

export ASAN_OPTIONS=detect_leaks=1:allocator_may_return_null=1:suppressions=$PWD/tests/asan.supp
export LSAN_OPTIONS=suppressions=$PWD/tests/lsan.supp
export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
export OMP_NUM_THREADS=1 BTFC_FORCE_CPU=1
REPORT="$B/fuzz-report.txt"
[ -n "$RUNS" ] && REPORT="$B/fuzz-smoke-report.txt"
printf "%-18s %8s %12s %9s %8s %8s %9s\n" target seconds executions exec/s corpus features findings | tee "$REPORT"
status=0
for t in "${TARGETS[@]}"; do
  work="$B/corpus/$t" art="$B/artifacts/$t"
  if [ -n "$RUNS" ]; then
    work="$B/smoke/$t" art="$B/smoke-artifacts/$t"
    rm -rf "$work" "$art"
  fi
  mkdir -p "$work" "$art"
  seeds=("tests/fuzz/corpus/$t")
  # Every golden model (one per codec, tests/golden/) seeds the container and loader targets, so
  # a new codec's golden file is fuzzed without editing this script.
  if [ "$t" = fuzz_container ]; then
    seeds+=(tests/golden)
  elif [ "$t" = fuzz_model_load ]; then
    mkdir -p "$B/corpus/golden_models"
    for g in tests/golden/*.btfc; do
      case "$g" in *.decoded.btfc|*/input.btfc) continue ;; esac
      { printf '\0'; cat "$g"; } >"$B/corpus/golden_models/$(basename "$g")"
    done
    seeds+=("$B/corpus/golden_models")
  fi
  log="$B/fuzz-$t.log"
  [ -n "$RUNS" ] && log="$B/smoke-$t.log"
  rc=0
  if [ -n "$RUNS" ]; then
    # A fixed seed: the smoke is a check (CI runs it), and the same mutations on every machine
    # make a finding there replay here with the same command. BTFC_FUZZ_SEED picks others.
    limit=(-runs="$(smoke_runs "$t")" -max_total_time=600 -seed="${BTFC_FUZZ_SEED:-1}")
  else
    limit=(-max_total_time="$SECONDS_PER")
  fi
  start=$EPOCHREALTIME
  nice -n 10 "$B/tests/fuzz/$t" "${limit[@]}" -print_final_stats=1 -timeout=20 \
    -rss_limit_mb=2048 -malloc_limit_mb=512 -max_len=65536 -artifact_prefix="$art/" $(target_opts "$t") \
    "$work" "${seeds[@]}" >"$log" 2>&1 || rc=$?
  secs=$(awk -v a="$start" -v b="$EPOCHREALTIME" 'BEGIN { printf "%.0f", b - a }')
  execs=$(grep 'stat::number_of_executed_units:' "$log" | awk '{print $2}' | tail -1)
  rate=$(grep 'stat::average_exec_per_sec:' "$log" | awk '{print $2}' | tail -1)
  last=$(grep -E '^#[0-9]+' "$log" | tail -1)
  files=$(echo "$last" | grep -o 'corp: [0-9]*' | awk '{print $2}')
  feats=$(echo "$last" | grep -o 'ft: [0-9]*' | awk '{print $2}')
  found=$(find "$art" -type f \( -name 'crash-*' -o -name 'leak-*' -o -name 'oom-*' -o -name 'timeout-*' \) | wc -l)
  [ "$rc" -ne 0 ] && [ "$found" -eq 0 ] && found="rc=$rc"
  printf "%-18s %8s %12s %9s %8s %8s %9s\n" "$t" "$secs" "${execs:-?}" "${rate:-?}" "${files:-?}" "${feats:-?}" "$found" | tee -a "$REPORT"
  if [ "$found" != 0 ]; then
    status=1
    # The target's own message and the sanitizer's summary (|| true: a finding without them must
    # not end the script under pipefail before the other targets ran). -a: a message may quote the
    # input's bytes, and grep >= 3.5 then says only "binary file matches", on stderr.
    grep -aE 'ERROR: |SUMMARY: |runtime error|^fuzz_' "$log" | head -5 | cut -c1-400 | sed 's/^/    /' || true
    # The input itself, so that a finding on another machine (CI) can be replayed from its log:
    # base64 -d >crash && BUILD/tests/fuzz/<target> crash.
    for a in $(find "$art" -type f \( -name 'crash-*' -o -name 'leak-*' -o -name 'oom-*' -o -name 'timeout-*' \) -size -16k | head -2); do
      echo "    $(basename "$a") (base64):"
      base64 -w 100 "$a" | sed 's/^/      /'
    done
  fi
done
exit $status
