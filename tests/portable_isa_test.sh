#!/usr/bin/env bash
# A portable build (BTFC_NATIVE=OFF, the default) must run on the baseline x86-64 CPU: outside
# the run-time dispatched functions (core/cpu_dispatch.h's clones "*.arch_x86_64_v3/v4", and the
# functions named "*_f16c" / "*_avx512" / "*_avx2" compiled with a target attribute and called only
# after a __builtin_cpu_supports check: the Bonn half conversions, core/thin_product.cpp's and
# core/sparse_sketch.cpp's kernels, fmf's eval and colour loops) no function of btfc's own binaries
# may hold an instruction that needs more than SSE2: no AVX / AVX-512 (VEX / EVEX encoded, "v"
# mnemonics, ymm / zmm registers), no BMI, no SSE4 / SSSE3. A stray -mavx2 on a file, an
# intrinsic outside a dispatched function or a new -march flag fails here, on the build machine,
# instead of as SIGILL on a user's older CPU. (tzcnt is allowed: it is GCC's `rep bsf`, which
# older CPUs run as bsf.)
#
# Usage: portable_isa_test.sh BINARY...   (exit 77, skipped, when objdump is missing)
set -uo pipefail
if [ "${BTFC_FORCE_CPU:-0}" = 1 ]; then
  echo "SKIP: the instruction-set check runs in the suite's first pass only (BTFC_FORCE_CPU=1 here)"; exit 77
fi
command -v objdump >/dev/null || { echo "objdump not found (binutils): cannot check the instruction sets"; exit 77; }
[ "$(uname -m)" = x86_64 ] || { echo "not x86-64: nothing to check"; exit 77; }
fail=0
for bin in "$@"; do
  [ -f "$bin" ] || { echo "FAIL $bin: not found"; fail=1; continue; }
  bad=$(objdump -d --no-show-raw-insn "$bin" | awk '
    /^[0-9a-f]+ <.*>:$/ { fn = $2; next }
    {
      m = $2
      if (m ~ /^v/ || $0 ~ /%[yz]mm[0-9]/ ||
          m ~ /^(popcnt|lzcnt|shlx|shrx|sarx|rorx|andn|bzhi|pdep|pext|movbe|blsr|blsi|blsmsk|crc32)$/ ||
          m ~ /^(pshufb|palignr|phadd[dw]|pmaddubsw|pmulhrsw|psign[bdw]|pabs[bdw])$/ ||
          m ~ /^(pmulld|ptest|pminsd|pmaxsd|pminud|pmaxud|pminsb|pmaxsb|pminuw|pmaxuw|pblendw|pblendvb|blendvp[sd]|blendp[sd]|roundp[sd]|rounds[sd]|dpp[sd]|insertps|extractps|pextr[bdq]|pinsr[bdq]|pmovsx|pmovzx|packusdw|pcmpeqq|pcmpgtq|movntdqa)/)
        if (fn !~ /arch_x86_64_v[34]/ && fn !~ /_f16c/ && fn !~ /_avx512/ && fn !~ /_avx2/) print fn " " m
    }' | sort -u)
  n_clones=$(objdump -t "$bin" 2>/dev/null | grep -c 'arch_x86_64_v[34]$' || true)
  if [ -n "$bad" ]; then
    echo "FAIL $bin: instructions beyond the baseline x86-64 outside the dispatched functions:"
    echo "$bad" | c++filt | head -20
    fail=1
  else
    echo "ok   $bin: baseline x86-64 outside $n_clones dispatched clones"
  fi
done
exit $fail
