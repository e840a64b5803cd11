// Run-time CPU dispatch for the hot loops of a portable build.
//
// btfc builds for the baseline x86-64 by default (BTFC_NATIVE=OFF), so a binary runs on any
// 64-bit x86 CPU. The loops that the compiler vectorizes and that dominate a command's time are
// marked BTFC_CPU_CLONES: GCC then compiles them three times (AVX-512 "x86-64-v4", AVX2 + FMA
// "x86-64-v3", baseline) and picks one when the program loads (an ifunc, resolved once, no
// per-call test). In a -march=native build (BTFC_NATIVE=ON), with another compiler or on another
// architecture the macro is empty and the loop is compiled once for the build's target.
//
// Contract for a marked function: it must not depend on the clone for its results beyond
// floating-point rounding, and where a caller relies on bitwise results (core/fixed_product.h)
// its file is compiled with -ffp-contract=off, so no clone fuses a multiply and an add and all
// clones produce the same bits.
//
// Eigen chooses its vector width from the compile flags, not per function, so Eigen code inside
// a clone stays baseline; the marked loops are plain C++ loops. Large products go to OpenBLAS,
// which dispatches by CPU itself.
#pragma once

#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) && defined(__linux__) && !defined(__AVX2__)
#define BTFC_CPU_CLONES __attribute__((target_clones("arch=x86-64-v4", "arch=x86-64-v3", "default")))
#define BTFC_CPU_DISPATCH 1
#else
#define BTFC_CPU_CLONES
#define BTFC_CPU_DISPATCH 0
#endif

namespace btfc {

// The instruction set the marked loops run with on this CPU: "x86-64-v4 (AVX-512)",
// "x86-64-v3 (AVX2)", "baseline", or "native (build flags)" when the build has no dispatch.
// For `btfc info --system` / bench headers: a benchmark row says which code ran.
const char* cpu_dispatch_level();

// Whether this CPU runs AVX-512F (tested once): the check before calling a hand-written kernel
// compiled with __attribute__((target("avx512f"))) (named *_avx512, core/thin_product.cpp,
// core/sparse_sketch.cpp). False where GCC's x86-64 CPU tests are not available.
bool cpu_has_avx512f();
// Whether this CPU runs AVX2 with FMA (tested once): the check before a hand-written *_avx2
// kernel (target("avx2,fma")), for CPUs without AVX-512 (core/thin_product.cpp,
// codecs/fmf/fmf_eval.cpp).
bool cpu_has_avx2_fma();
// Whether this is an Intel CPU (tested once): B X's kernel is chosen by vendor and model
// (core/thin_product.cpp), where the CPUs measured differ.
bool cpu_is_intel();
// Whether this is an AMD Zen 1 / Zen+ (family 17h before Zen 2; its 256-bit operations run as two
// 128-bit halves), tested once: the CPU without AVX-512 where B X's AVX2 tiles beat OpenBLAS.
bool cpu_is_zen1();

}  // namespace btfc
