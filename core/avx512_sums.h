// Sums of float vectors (in double, or float lanes), for the hand-written AVX-512 kernels
// (core/thin_product.cpp, core/sparse_sketch.cpp): include only on
// x86-64 with GCC, call only from code compiled with target("avx512f").
//
// Written with the full-mask maskz intrinsics (the low half too: codecs/fmf/fmf_color.cpp does
// the same): GCC 12's unmasked _mm512_cvtps_pd, _mm512_extractf64x4_pd, _mm512_castps512_ps256
// and _mm512_reduce_add_pd pass an undefined source to their builtins (its bug 105593) and warn
// -Wmaybe-uninitialized in every build.
#pragma once
#include <immintrin.h>

namespace btfc {

// s0 += (double) v[0..8)^2, s1 += (double) v[8..16)^2 (lane by lane, one FMA each).
__attribute__((target("avx512f"), always_inline)) inline void add_squares_pd(__m512 v, __m512d& s0, __m512d& s1) {
  const __m512d lo = _mm512_maskz_cvtps_pd(0xff, _mm256_castpd_ps(_mm512_maskz_extractf64x4_pd(0xf, _mm512_castps_pd(v), 0)));
  const __m512d hi = _mm512_maskz_cvtps_pd(0xff, _mm256_castpd_ps(_mm512_maskz_extractf64x4_pd(0xf, _mm512_castps_pd(v), 1)));
  s0 = _mm512_fmadd_pd(lo, lo, s0);
  s1 = _mm512_fmadd_pd(hi, hi, s1);
}

// The sum of the 8 lanes in _mm512_reduce_add_pd's order (halves, then quarters, then the pair).
__attribute__((target("avx512f"), always_inline)) inline double reduce_add_pd(__m512d v) {
  const __m256d h = _mm256_add_pd(_mm512_maskz_extractf64x4_pd(0xf, v, 1), _mm512_maskz_extractf64x4_pd(0xf, v, 0));
  const __m128d q = _mm_add_pd(_mm256_extractf128_pd(h, 1), _mm256_castpd256_pd128(h));
  return _mm_cvtsd_f64(q) + _mm_cvtsd_f64(_mm_unpackhi_pd(q, q));
}

// The sum of the 16 lanes in _mm512_reduce_add_ps's order (halves, quarters, pairs, the pair).
__attribute__((target("avx512f"), always_inline)) inline float reduce_add_ps(__m512 v) {
  const __m512d d = _mm512_castps_pd(v);
  const __m256 h = _mm256_add_ps(_mm256_castpd_ps(_mm512_maskz_extractf64x4_pd(0xf, d, 1)), _mm256_castpd_ps(_mm512_maskz_extractf64x4_pd(0xf, d, 0)));
  const __m128 q = _mm_add_ps(_mm256_extractf128_ps(h, 1), _mm256_castps256_ps128(h));
  const __m128 p = _mm_add_ps(q, _mm_shuffle_ps(q, q, _MM_SHUFFLE(1, 0, 3, 2)));
  return _mm_cvtss_f32(p) + _mm_cvtss_f32(_mm_shuffle_ps(p, p, _MM_SHUFFLE(1, 1, 1, 1)));
}

}  // namespace btfc
