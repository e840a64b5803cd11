// A matrix product whose every output value has the same bits however the work is grouped.
//
// out (n x m, row stride ldo) = A (n x C, row stride lda) * BT (C x m, row stride m).
//
// Contract: out(i, r) is computed as ((A(i,0) BT(0,r) + A(i,1) BT(1,r)) + ...) + A(i,C-1) BT(C-1,r),
// in increasing k, starting from 0 (or from out(i, r) with accumulate = true), one multiply and one
// add per term (this file is compiled with -ffp-contract=off, see CMakeLists.txt). So the value of
// a row depends only on that row of A and on BT: not on n, on where the row sits in a block, on
// the thread count, or on which BLAS kernel the CPU selects. Decoders use it so that a model
// decoded in bands (streamed decompress, region decodes, out-of-core compare) gives exactly the
// bytes of a whole decode. A GEMM (OpenBLAS) is free to pick edge kernels and K splits by shape,
// and did: a streamed decode differed from the whole one by one float ulp on another CPU's
// kernels (issue 23).
//
// Speed: register-blocked 4 rows x 32 columns, vectorized over columns by the compiler (AVX-512 /
// AVX2 / SSE2 chosen at run time in a portable build, core/cpu_dispatch.h), rows in parallel
// (OpenMP). It is for decodes (C up to a few hundred), not for factorizations.
#pragma once
#include <cstddef>

namespace btfc {

void fixed_order_product(const float* A, size_t n, size_t C, size_t lda, const float* BT, size_t m, float* out, size_t ldo,
                         bool accumulate = false);

}  // namespace btfc
