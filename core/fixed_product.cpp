// See fixed_product.h. Both paths below (the full 4 x 32 block and the ragged edge) perform the
// same operations per output value in the same order, so a value does not depend on which path
// computed it.
#include "core/fixed_product.h"

#include "core/cpu_dispatch.h"

#include <algorithm>
#include <cstdint>

namespace btfc {
namespace {

constexpr size_t kRows = 4, kCols = 32;

// The full block: acc[t][j] += A(i0 + t, k) * BT(k, r0 + j) for k = 0..C-1.
// Dispatched by CPU (core/cpu_dispatch.h): the 32 columns are one AVX-512 or two AVX2 registers
// per row. With -ffp-contract=off every clone computes the same bits. A block does C x 128
// multiply-adds, so the indirect call costs nothing measurable.
BTFC_CPU_CLONES void block_full(const float* A, size_t C, size_t lda, const float* BT, size_t m, float* out, size_t ldo, bool accumulate) {
  float acc[kRows][kCols];
  for (size_t t = 0; t < kRows; ++t)
    for (size_t j = 0; j < kCols; ++j) acc[t][j] = accumulate ? out[t * ldo + j] : 0.0f;
  for (size_t k = 0; k < C; ++k) {
    const float* b = BT + k * m;
    for (size_t t = 0; t < kRows; ++t) {
      const float a = A[t * lda + k];
      for (size_t j = 0; j < kCols; ++j) acc[t][j] += a * b[j];
    }
  }
  for (size_t t = 0; t < kRows; ++t)
    for (size_t j = 0; j < kCols; ++j) out[t * ldo + j] = acc[t][j];
}

// A ragged block (nr rows, nc columns): the same per-value arithmetic.
BTFC_CPU_CLONES void block_edge(const float* A, size_t nr, size_t nc, size_t C, size_t lda, const float* BT, size_t m, float* out, size_t ldo,
                bool accumulate) {
  float acc[kRows][kCols];
  for (size_t t = 0; t < nr; ++t)
    for (size_t j = 0; j < nc; ++j) acc[t][j] = accumulate ? out[t * ldo + j] : 0.0f;
  for (size_t k = 0; k < C; ++k) {
    const float* b = BT + k * m;
    for (size_t t = 0; t < nr; ++t) {
      const float a = A[t * lda + k];
      for (size_t j = 0; j < nc; ++j) acc[t][j] += a * b[j];
    }
  }
  for (size_t t = 0; t < nr; ++t)
    for (size_t j = 0; j < nc; ++j) out[t * ldo + j] = acc[t][j];
}

}  // namespace

void fixed_order_product(const float* A, size_t n, size_t C, size_t lda, const float* BT, size_t m, float* out, size_t ldo,
                         bool accumulate) {
  // Cache blocking: a chunk of kChunk rows of A (kChunk x C floats, in L1/L2) meets every
  // 32-column slice of BT (C x 32 floats, in L1) before the next chunk starts, so BT is read
  // from memory once per chunk, not once per 4 rows. The order of the sums is unchanged.
  constexpr size_t kChunk = 128;
  const int64_t chunks = int64_t((n + kChunk - 1) / kChunk);
#pragma omp parallel for schedule(static) if (chunks > 1 && n * m * C > (size_t(1) << 16))
  for (int64_t ch = 0; ch < chunks; ++ch) {
    const size_t c0 = size_t(ch) * kChunk, c1 = std::min(n, c0 + kChunk);
    for (size_t r0 = 0; r0 < m; r0 += kCols) {
      const size_t nc = std::min(kCols, m - r0);
      for (size_t i0 = c0; i0 < c1; i0 += kRows) {
        const size_t nr = std::min(kRows, c1 - i0);
        const float* a = A + i0 * lda;
        float* o = out + i0 * ldo + r0;
        if (nr == kRows && nc == kCols) block_full(a, C, lda, BT + r0, m, o, ldo, accumulate);
        else block_edge(a, nr, nc, C, lda, BT + r0, m, o, ldo, accumulate);
      }
    }
  }
}

}  // namespace btfc
