# Shared helpers of the CLI test scripts (sourced; W and fails are the caller's).
# check NAME EXPECTED_EXIT CMD...: runs CMD, its stdout in $W/out.txt and stderr in $W/err.txt,
# and counts a failure (printing both) when the exit code is not the expected one.
check() {
  local name=$1 want=$2; shift 2
  "$@" >"$W/out.txt" 2>"$W/err.txt"
  local got=$?
  if [ "$got" -ne "$want" ]; then
    echo "FAIL $name: exit $got, wanted $want"; cat "$W/out.txt" "$W/err.txt"; fails=$((fails + 1))
  else
    echo "ok   $name"
  fi
}
# expect_grep NAME PATTERN FILE: counts a failure when PATTERN is not in FILE.
expect_grep() {
  if ! grep -q -- "$2" "$3"; then echo "FAIL $1: '$2' not in $3:"; cat "$3"; fails=$((fails + 1)); else echo "ok   $1"; fi
}
