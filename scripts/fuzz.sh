#!/usr/bin/env bash
# Builds the libFuzzer targets (tests/fuzz/, BTFC_FUZZ=ON, clang + ASan + UBSan) into build-fuzz/
# and runs each for SECONDS (default 60), one after another, niced, on one thread. A benchmark-
# style script, not part of CI. Prints per target: executions, exec/s, corpus size (files and
# coverage features) and findings (crash-*, leak-*, oom-*, timeout-* artifacts), and writes the
# table to build-fuzz/fuzz-report.txt. Exit status 1 when any target found something.
#
# Usage: scripts/fuzz.sh [SECONDS] [TARGET...]      e.g. scripts/fuzz.sh 600
#        targets: fuzz_container fuzz_model_load fuzz_bonn fuzz_image_name fuzz_spec
# A finding is reproduced with: build-fuzz/tests/fuzz/<target> build-fuzz/artifacts/<target>/crash-...
set -euo pipefail
cd "$(dirname "$0")/.."
SECONDS_PER=${1:-60}
shift || true
TARGETS=("$@")
[ ${#TARGETS[@]} -eq 0 ] && TARGETS=(fuzz_container fuzz_model_load fuzz_bonn fuzz_image_name fuzz_spec)

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
nice -n 10 cmake --build "$B" -j 2 --target "${TARGETS[@]}"

export ASAN_OPTIONS=detect_leaks=1:allocator_may_return_null=1
export LSAN_OPTIONS=suppressions=$PWD/tests/lsan.supp
export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
export OMP_NUM_THREADS=1 BTFC_FORCE_CPU=1
REPORT="$B/fuzz-report.txt"
printf "%-16s %8s %12s %9s %8s %8s %9s\n" target seconds executions exec/s corpus features findings | tee "$REPORT"
status=0
for t in "${TARGETS[@]}"; do
  work="$B/corpus/$t" art="$B/artifacts/$t"
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
  rc=0
  nice -n 10 "$B/tests/fuzz/$t" -max_total_time="$SECONDS_PER" -print_final_stats=1 -timeout=20 \
    -rss_limit_mb=2048 -malloc_limit_mb=512 -max_len=65536 -artifact_prefix="$art/" \
    "$work" "${seeds[@]}" >"$log" 2>&1 || rc=$?
  execs=$(grep 'stat::number_of_executed_units:' "$log" | awk '{print $2}' | tail -1)
  rate=$(grep 'stat::average_exec_per_sec:' "$log" | awk '{print $2}' | tail -1)
  last=$(grep -E '^#[0-9]+' "$log" | tail -1)
  files=$(echo "$last" | grep -o 'corp: [0-9]*' | awk '{print $2}')
  feats=$(echo "$last" | grep -o 'ft: [0-9]*' | awk '{print $2}')
  found=$(find "$art" -type f \( -name 'crash-*' -o -name 'leak-*' -o -name 'oom-*' -o -name 'timeout-*' \) | wc -l)
  [ "$rc" -ne 0 ] && [ "$found" -eq 0 ] && found="rc=$rc"
  printf "%-16s %8s %12s %9s %8s %8s %9s\n" "$t" "$SECONDS_PER" "${execs:-?}" "${rate:-?}" "${files:-?}" "${feats:-?}" "$found" | tee -a "$REPORT"
  if [ "$found" != 0 ]; then
    status=1
    grep -E 'ERROR: |SUMMARY: |runtime error' "$log" | head -5 | sed 's/^/    /'
  fi
done
exit $status
