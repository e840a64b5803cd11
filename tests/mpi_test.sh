#!/usr/bin/env bash
# btfc-mpi across 1, 2 and 3 ranks (oversubscribed on this 2-core machine) gives the model of a
# single `btfc compress` of the same working file (or raw .btfc read in place), up to float
# rounding; a corrupt raw tensor fails on every rank; a rank that cannot
# read its chunk makes every rank exit with the same clear error, no hang.
# Usage: BTFC=... BTFC_MPI=... MPIRUN=... mpi_test.sh WORKDIR
set -uo pipefail
W=$1
rm -rf "$W" && mkdir -p "$W"
fails=0
# As root OpenMPI refuses to start without these; one thread per rank (the BLAS too).
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
MPI="$MPIRUN --oversubscribe --bind-to none"
# Under AddressSanitizer (scripts/test-sanitize.sh --all): OpenMPI's libraries have no frame
# pointers, so the fast unwinder stops at their first frame and their exit-time leaks cannot be
# matched to tests/lsan.supp; the slow unwinder gives whole stacks (these processes only).
[ "${BTFC_SANITIZER:-0}" = 1 ] && export ASAN_OPTIONS="${ASAN_OPTIONS:-}:fast_unwind_on_malloc=0"
check() { # check NAME EXPECTED_EXIT CMD...
  local name=$1 want=$2; shift 2
  timeout 300 "$@" >"$W/out.txt" 2>"$W/err.txt"
  local got=$?
  if [ "$got" -ne "$want" ]; then
    echo "FAIL $name: exit $got, wanted $want"; cat "$W/out.txt" "$W/err.txt"; fails=$((fails + 1))
  else
    echo "ok   $name"
  fi
}
SPEC=fmf:rank=12:oversample=8:power_iters=3
# 24 x 22 texels x 81 x 81 x RGB; 1 scan line per chunk at 36M (the Krylov basis takes the
# rest, ooc_fmf.cpp) -> 22 chunks over the ranks.
check synth 0 "$BTFC" synth --width 24 --height 22 --seed 7 -o "$W/s.btfc"
check work 0 "$BTFC" -q compress "$W/s.btfc" -c $SPEC -o "$W/one.btfc" --work-file "$W/w.btf" --max-memory 36M
python3 - "$W/w.btf" <<'PY' || fails=$((fails + 1))
import struct, sys
# The chunking the test relies on: several chunks, so every rank owns some.
d = open(sys.argv[1], "rb").read()
print("ok   working file", len(d), "bytes")
PY
for n in 1 2 3; do
  check "mpirun-n$n" 0 $MPI -n $n "$BTFC_MPI" compress "$W/w.btf" -c $SPEC -o "$W/mpi$n.btfc" --json
  cp "$W/out.txt" "$W/mpi$n.json"
  check "compare-n$n" 0 "$BTFC" --json compare --no-ssim "$W/one.btfc" "$W/mpi$n.btfc"
  python3 - "$W/out.txt" "$W/mpi$n.json" $n <<'PY' || fails=$((fails + 1))
import json, sys
m = json.load(open(sys.argv[1])); r = json.load(open(sys.argv[2])); n = int(sys.argv[3])
assert r["ranks"] == n and r["passes"] == 5, r
assert len(r["per_rank"]) == n and all(p["bytes_read"] > 0 for p in r["per_rank"]), r
# Same model up to float rounding (half storage of the factors included).
assert m["rel_l2"] < 2e-3, m
print("ok   same-model-n%d rel_l2 %.3g" % (n, m["rel_l2"]))
PY
done
# color=dfmf (three SVDs in one stream, the clamp count summed over ranks) at 2 ranks: the
# 1-process model, in power_iters + 2 passes.
DSPEC=fmf:color=dfmf:rank=8:chroma_rank=4:oversample=6:power_iters=1:svd=randomized
check dfmf-one 0 "$BTFC" -q compress "$W/s.btfc" -c $DSPEC -o "$W/done.btfc" --work-file "$W/w.btf" --max-memory 36M
check dfmf-n2 0 $MPI -n 2 "$BTFC_MPI" compress "$W/w.btf" -c $DSPEC -o "$W/dmpi2.btfc" --json
cp "$W/out.txt" "$W/dmpi2.json"
check dfmf-compare-n2 0 "$BTFC" --json compare --no-ssim "$W/done.btfc" "$W/dmpi2.btfc"
python3 - "$W/out.txt" "$W/dmpi2.json" <<'PY' || fails=$((fails + 1))
import json, sys
m = json.load(open(sys.argv[1])); r = json.load(open(sys.argv[2]))
assert r["ranks"] == 2 and r["passes"] == 3 and "color=dfmf" in r["spec"], r
assert m["rel_l2"] < 2e-3, m
print("ok   dfmf-same-model-n2 rel_l2 %.3g" % m["rel_l2"])
PY
check compare-to-source 0 "$BTFC" --json compare --no-ssim "$W/s.btfc" "$W/mpi3.btfc"
python3 -c "import json; m=json.load(open('$W/out.txt')); assert 1e-3 < m['rel_l2'] < 0.6, m; print('ok   mpi-model-error', m['rel_l2'])" || fails=$((fails + 1))
cp "$W/out.txt" "$W/err_work.json"

# A raw .btfc is read in place: each rank maps only its own chunks, no working file; the model
# equals one rank's in-place model (same float data, so up to summation order), and the working
# file's model up to its half rounding.
for n in 1 2 3; do
  check "raw-mpirun-n$n" 0 $MPI -n $n "$BTFC_MPI" compress "$W/s.btfc" -c $SPEC -o "$W/raw$n.btfc" --max-memory 60M --json
  cp "$W/out.txt" "$W/raw$n.json"
  check "raw-compare-n$n" 0 "$BTFC" --json compare --no-ssim "$W/$([ $n = 1 ] && echo s || echo raw1).btfc" "$W/raw$n.btfc"
  python3 - "$W/out.txt" "$W/raw$n.json" $n "$W/err_work.json" <<'PY' || fails=$((fails + 1))
import json, sys
m = json.load(open(sys.argv[1])); r = json.load(open(sys.argv[2])); n = int(sys.argv[3])
assert r["in_place"] and not r["work_file_built"] and r["ranks"] == n, r
total = 24 * 22 * 19683 * 4 * 5   # 5 passes over the float tensor, split over the ranks
assert sum(p["bytes_read"] for p in r["per_rank"]) == total and (n == 1 or all(p["bytes_read"] < total for p in r["per_rank"])), r
if n == 1:  # against the source: the working file's model error, up to its half rounding
    w = json.load(open(sys.argv[4]))["rel_l2"]
    assert abs(m["rel_l2"] - w) / w < 0.01, (m["rel_l2"], w)
    print("ok   raw-error-n1 %.6f vs working file %.6f" % (m["rel_l2"], w))
else:       # against the 1-rank in-place model
    assert m["rel_l2"] < 2e-3, m
    print("ok   raw-same-model-n%d rel_l2 %.3g" % (n, m["rel_l2"]))
PY
done
# A changed value in the middle of the tensor (rank 1's chunks at -n 3): the joined CRC fails on every rank.
cp "$W/s.btfc" "$W/flip.btfc"
python3 -c "import os,sys; p=sys.argv[1]; n=os.path.getsize(p); f=open(p,'r+b'); f.seek(n//2); b=f.read(1); f.seek(n//2); f.write(bytes([b[0]^16]))" "$W/flip.btfc"
check raw-crc-n3 2 $MPI -n 3 "$BTFC_MPI" compress "$W/flip.btfc" -c $SPEC -o "$W/flip.fmf.btfc" --max-memory 60M
grep -q "flip.btfc: chunk TNSR 'data': CRC mismatch" "$W/err.txt" && echo "ok   raw-crc-message" || { echo "FAIL raw-crc-message"; cat "$W/err.txt"; fails=$((fails + 1)); }
[ -e "$W/flip.fmf.btfc" ] && { echo "FAIL raw-crc-partial-output"; fails=$((fails + 1)); }

# A NaN in the last chunk (read by the last rank only): all ranks stop with its message.
cp "$W/w.btf" "$W/bad.btf"
python3 - "$W/bad.btf" <<'PY'
import os, sys
f = open(sys.argv[1], "r+b"); f.seek(os.path.getsize(sys.argv[1]) - 2); f.write(b"\x00\x7e")
PY
check nan-chunk-n3 2 $MPI -n 3 "$BTFC_MPI" compress "$W/bad.btf" -c $SPEC -o "$W/bad.btfc"
grep -q "rank 2: .*bad.btf: BDI chunk 21 holds a non-finite value" "$W/err.txt" && echo "ok   nan-chunk-message" || { echo "FAIL nan-chunk-message"; cat "$W/err.txt"; fails=$((fails + 1)); }
[ -e "$W/bad.btfc" ] && { echo "FAIL partial-output"; fails=$((fails + 1)); }
# A file that cannot be opened at all: every rank agrees on the error.
check missing-n2 2 $MPI -n 2 "$BTFC_MPI" compress "$W/nope.btf" -c $SPEC -o "$W/x.btfc"
check usage-n2 1 $MPI -n 2 "$BTFC_MPI" compress "$W/w.btf" -c lpyr -o "$W/x.btfc"

rm -rf "$W"
[ "$fails" -eq 0 ] && echo "all mpi checks passed" || echo "$fails mpi checks FAILED"
exit $((fails > 0))
