#!/usr/bin/env bash
# Every command line of the README's "Using btfc" block, run as written, in order, in a fresh
# folder (issue 23: "make every README line a test that runs it"). The lines are read from the
# README itself, so a line that is edited is tested as edited and a new line is tested too.
# Only what a copy-paste user would have differently is adapted:
#   - `build/` is this build's folder, `../shared/` the source tree's data, `docs/` and
#     `scripts/` the source tree's (symlinks in the work folder);
#   - the "big" inputs are small stand-ins made here (a 16 x 16 synthetic BTF `big.btfc` and
#     its image set `big/`), so `--max-memory 1G` runs them in core; the streamed paths have
#     their own tests (stream_cli, mpi_ranks);
#   - `mpirun` is allowed to run as root and to oversubscribe this 2-core machine (the
#     variables mpi_test.sh sets), and is skipped when btfc-mpi was not built;
#   - `scripts/bench-all.sh` (tens of minutes) is not run here: it is a benchmark.
# Usage: BTFC=path/to/btfc SOURCE_DIR=... readme_test.sh WORKDIR
set -uo pipefail
W=$1
# Once per suite run (3 minutes on 2 cores, the suite's longest test): the README's lines are
# about usage; the CPU pass (BTFC_FORCE_CPU=1) would run the same lines on the CPU path, which the
# codec and CLI tests of that pass already cover.
if [ "${BTFC_FORCE_CPU:-0}" = 1 ]; then
  echo "SKIP: the README's lines run in the suite's first pass only (BTFC_FORCE_CPU=1 here)"; exit 77
fi
SRC=$(realpath "$SOURCE_DIR")
BUILD=$(dirname "$(realpath "$BTFC")")
rm -rf "$W" && mkdir -p "$W"
fails=0
ran=0
cd "$W" || exit 1
ln -s "$SRC/docs" docs
ln -s "$SRC/scripts" scripts
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1

# The stand-ins for the README's big inputs.
"$BTFC" -q synth --width 16 --height 16 --seed 3 -o big.btfc || { echo "FAIL fixture big.btfc"; exit 1; }
"$BTFC" -q synth --width 16 --height 16 --seed 3 -o big || { echo "FAIL fixture big/"; exit 1; }

# The second ```sh block of the README ("Using btfc"), continuation lines joined.
lines=$(awk '/^```sh/{n++; if (n == 2) {f = 1; next}} /^```/{f = 0} f' "$SRC/README.md" | sed -e ':a' -e '/\\$/N; s/\\\n//; ta')
[ -n "$lines" ] || { echo "FAIL no command block found in README.md"; exit 1; }
while IFS= read -r line; do
  cmd=${line%%#*}                                   # the comment after the command
  cmd=$(echo "$cmd" | sed -e 's/[[:space:]]*$//')
  [ -z "$cmd" ] && continue
  case "$cmd" in
    B=*) continue ;;                                # B=build/btfc: this build's btfc below
    scripts/bench-all.sh*) echo "skip $cmd (a benchmark: tens of minutes)"; continue ;;
    mpirun*) [ -x "$BUILD/btfc-mpi" ] && command -v mpirun >/dev/null || { echo "skip $cmd (no btfc-mpi)"; continue; } ;;
  esac
  run=${cmd//build\//$BUILD/}
  run=${run//\$B/$BTFC}
  run=${run//..\/shared\//$SRC/..\/shared\/}
  ran=$((ran + 1))
  if timeout 600 bash -c "$run" </dev/null >out.txt 2>err.txt; then  # stdin: mpirun would eat the lines
    echo "ok   $cmd"
  else
    echo "FAIL $cmd (exit $?)"; tail -5 out.txt err.txt; fails=$((fails + 1))
  fi
done <<<"$lines"

[ "$ran" -ge 29 ] || { echo "FAIL only $ran README lines found (the block moved?)"; fails=$((fails + 1)); }
echo "$ran README line(s) run, $fails failure(s)"
[ "$fails" -eq 0 ]
