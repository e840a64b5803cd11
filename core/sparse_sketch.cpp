// The sparse sign sketch S^T B; see sparse_sketch.h for the contract and the sources.
#include "core/sparse_sketch.h"

#include "core/cpu_dispatch.h"

#include <algorithm>
#include <random>

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>

#include "core/avx512_sums.h"
#define BTFC_SKETCH_AVX512 1
#endif

namespace btfc {

namespace {
constexpr size_t k_max_groups = 64;  // s <= 1024: the per-texel sums stay in L1 (4 KB)
constexpr size_t k_texels = 64;     // texels per parallel task: a contiguous 64-column range of B
constexpr size_t k_ahead = 2048;    // software prefetch distance in floats (8 KB: measured 1-8 KB alike)

// Layer t of the block of row groups starting at b0 into the texel's bucket sums w, one value at
// a time (the reference's order; the vector loops take it for a partial last block).
inline void add_block_reference(const float* col, size_t m, const SparseSign& S, size_t q_all, size_t b0, size_t t, float* w,
                                bool energy, double& e) {
  const size_t groups = S.s / 16;
  for (size_t k = 0; k < groups && b0 + k < q_all; ++k) {
    const size_t q = b0 + S.pick[t * q_all + b0 + k];
    const uint16_t negative = S.negative[t * q_all + q];
    for (size_t r = 0; r < 16 && 16 * q + r < m; ++r) {
      const float v = (negative >> r) & 1 ? -col[16 * q + r] : col[16 * q + r];
      w[16 * k + r] += v;
      if (energy && t == 0) e += double(v) * double(v);
    }
  }
}

#ifdef BTFC_SKETCH_AVX512
// One vector of 16 rows (row group q) into its bucket group's accumulator, its squares into the
// energy (in double, so it matches squared_norm to round-off).
__attribute__((target("avx512f"))) inline void sketch_add_avx512(const uint16_t* negative, const float* col, size_t q, __m512& acc,
                                                                __m512d& s0, __m512d& s1, bool energy, size_t rows) {
  __m512 v = rows >= 16 ? _mm512_loadu_ps(col + 16 * q) : _mm512_maskz_loadu_ps(__mmask16((1u << rows) - 1), col + 16 * q);
  v = _mm512_mask_sub_ps(v, __mmask16(negative[q]), _mm512_setzero_ps(), v);
  acc = _mm512_add_ps(acc, v);
  if (energy) {
    add_squares_pd(v, s0, s1);
  }
}

// Texels [j0, j1), one sequential read of their columns. G > 0: G bucket groups, known at
// compile time, so the accumulators are registers; G = 0: S.s / 16 of them in memory (L1).
template <int G>
__attribute__((target("avx512f"))) double sketch_avx512(const float* B, size_t m, const SparseSign& S, size_t j0, size_t j1, float* W,
                                                      bool energy) {
  const size_t groups = G > 0 ? size_t(G) : S.s / 16, q_all = (m + 15) / 16;
  __m512 acc[G > 0 ? G : k_max_groups];
  double e = 0;
  for (size_t j = j0; j < j1; ++j) {
    const float* col = B + j * m;
    for (size_t k = 0; k < groups; ++k) acc[k] = _mm512_setzero_ps();
    __m512d s0 = _mm512_setzero_pd(), s1 = _mm512_setzero_pd();
    size_t b0 = 0;
    for (; b0 + groups <= q_all && 16 * (b0 + groups) <= m; b0 += groups) {  // whole blocks of whole groups
#pragma GCC unroll 24
      for (size_t k = 0; k < groups; ++k) {
        // The block is read in shuffled order, which the hardware prefetcher does not follow:
        // fetch ahead in memory order (past the column's end is the next column: B is contiguous).
        _mm_prefetch(reinterpret_cast<const char*>(col + 16 * (b0 + k) + k_ahead), _MM_HINT_T0);
        sketch_add_avx512(S.negative.data(), col, b0 + S.pick[b0 + k], acc[k], s0, s1, energy, 16);
      }
      for (size_t t = 1; t < S.layers; ++t) {  // the other layers: the block again, from L1
        const uint32_t* pick = S.pick.data() + t * q_all + b0;
        const uint16_t* negative = S.negative.data() + t * q_all;
#pragma GCC unroll 24
        for (size_t k = 0; k < groups; ++k) sketch_add_avx512(negative, col, b0 + pick[k], acc[k], s0, s1, false, 16);
      }
    }
    for (size_t t = 0; t < S.layers; ++t)  // the last block
      for (size_t k = 0; b0 + k < q_all; ++k) {
        const size_t q = b0 + S.pick[t * q_all + b0 + k];
        sketch_add_avx512(S.negative.data() + t * q_all, col, q, acc[k], s0, s1, energy && t == 0, std::min<size_t>(16, m - 16 * q));
      }
    for (size_t k = 0; k < groups; ++k) _mm512_storeu_ps(W + j * S.s + 16 * k, acc[k]);
    if (energy) e += reduce_add_pd(_mm512_add_pd(s0, s1));
  }
  return e;
}

// The same for AVX2 (CPUs without AVX-512; the 16 registers cannot hold the bucket sums, so they
// stay in the texel's row of W, in L1). A row group's signs flip as the reference's (the sign
// bit), and each bucket adds its rows in the reference's order, so W is the same bits. The last
// block (possibly partial) takes the reference's loop.
__attribute__((target("avx2,fma"))) double sketch_avx2(const float* B, size_t m, const SparseSign& S, size_t j0, size_t j1, float* W,
                                                     bool energy) {
  const size_t groups = S.s / 16, q_all = (m + 15) / 16;
  const __m256i bit_lo = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128), bit_hi = _mm256_slli_epi32(bit_lo, 8);
  const __m256i sign = _mm256_set1_epi32(int(0x80000000u));
  double e = 0;
  for (size_t j = j0; j < j1; ++j) {
    const float* col = B + j * m;
    float* w = W + j * S.s;
    std::fill(w, w + S.s, 0.0f);
    __m256d s0 = _mm256_setzero_pd(), s1 = _mm256_setzero_pd();
    size_t b0 = 0;
    for (; b0 + groups <= q_all && 16 * (b0 + groups) <= m; b0 += groups)  // whole blocks of whole groups
      for (size_t t = 0; t < S.layers; ++t) {
        const uint32_t* pick = S.pick.data() + t * q_all + b0;
        const uint16_t* negative = S.negative.data() + t * q_all;
        for (size_t k = 0; k < groups; ++k) {
          if (t == 0) _mm_prefetch(reinterpret_cast<const char*>(col + 16 * (b0 + k) + k_ahead), _MM_HINT_T0);
          const size_t q = b0 + pick[k];
          const __m256i bits = _mm256_set1_epi32(int(negative[q]));
          const __m256 f0 = _mm256_castsi256_ps(_mm256_and_si256(_mm256_cmpeq_epi32(_mm256_and_si256(bits, bit_lo), bit_lo), sign));
          const __m256 f1 = _mm256_castsi256_ps(_mm256_and_si256(_mm256_cmpeq_epi32(_mm256_and_si256(bits, bit_hi), bit_hi), sign));
          const __m256 v0 = _mm256_xor_ps(_mm256_loadu_ps(col + 16 * q), f0), v1 = _mm256_xor_ps(_mm256_loadu_ps(col + 16 * q + 8), f1);
          _mm256_storeu_ps(w + 16 * k, _mm256_add_ps(_mm256_loadu_ps(w + 16 * k), v0));
          _mm256_storeu_ps(w + 16 * k + 8, _mm256_add_ps(_mm256_loadu_ps(w + 16 * k + 8), v1));
          if (energy && t == 0) {
            const __m256d a = _mm256_cvtps_pd(_mm256_castps256_ps128(v0)), b = _mm256_cvtps_pd(_mm256_extractf128_ps(v0, 1));
            const __m256d c = _mm256_cvtps_pd(_mm256_castps256_ps128(v1)), d = _mm256_cvtps_pd(_mm256_extractf128_ps(v1, 1));
            s0 = _mm256_fmadd_pd(a, a, s0), s1 = _mm256_fmadd_pd(b, b, s1);
            s0 = _mm256_fmadd_pd(c, c, s0), s1 = _mm256_fmadd_pd(d, d, s1);
          }
        }
      }
    for (size_t t = 0; t < S.layers; ++t) add_block_reference(col, m, S, q_all, b0, t, w, energy, e);  // the last block
    if (energy) {
      alignas(32) double t4[4];
      _mm256_store_pd(t4, _mm256_add_pd(s0, s1));
      e += (t4[0] + t4[1]) + (t4[2] + t4[3]);
    }
  }
  return e;
}
#endif

// The same sums in the same order (each bucket adds its rows block by block, layer by layer
// within a block), one value at a time.
double sketch_portable(const float* B, size_t m, const SparseSign& S, size_t j0, size_t j1, float* W, bool energy) {
  const size_t groups = S.s / 16, q_all = (m + 15) / 16;
  double e = 0;
  for (size_t j = j0; j < j1; ++j) {
    const float* col = B + j * m;
    float* w = W + j * S.s;
    std::fill(w, w + S.s, 0.0f);
    for (size_t b0 = 0; b0 < q_all; b0 += groups)
      for (size_t t = 0; t < S.layers; ++t) add_block_reference(col, m, S, q_all, b0, t, w, energy, e);
  }
  return e;
}
}  // namespace

SparseSign make_sparse_sign(size_t m, size_t s, uint64_t seed, size_t layers) {
  SparseSign S;
  S.m = m;
  S.s = std::min(k_max_groups * 16, std::max<size_t>(16, (s + 15) / 16 * 16));
  S.layers = std::max<size_t>(1, layers);
  const size_t groups = S.s / 16, q = (m + 15) / 16;
  std::mt19937_64 rng(seed ^ 0x5DEECE66DULL);
  S.pick.resize(S.layers * q);
  S.negative.resize(S.layers * q);
  // Fisher-Yates per block and layer on raw 64-bit draws (no standard-library distribution, so
  // the map is the same with every standard library).
  for (size_t t = 0; t < S.layers; ++t)
    for (size_t b0 = 0; b0 < q; b0 += groups) {
      uint32_t* pick = S.pick.data() + t * q + b0;
      const size_t size = std::min(groups, q - b0);
      for (size_t k = 0; k < size; ++k) pick[k] = uint32_t(k);
      for (size_t k = size; k > 1; --k) std::swap(pick[k - 1], pick[rng() % k]);
    }
  for (uint16_t& x : S.negative) x = uint16_t(rng() >> 48);
  return S;
}

namespace {
// simd: 0 the reference loop, 1 the best this CPU runs, 2 the AVX2 loop (tests).
void sketch(const float* B, size_t n, const SparseSign& S, float* W, double* energy, int simd) {
  const size_t m = S.m;
  const int64_t tasks = int64_t((n + k_texels - 1) / k_texels);
  std::vector<double> part(size_t(tasks), 0.0);
#ifdef BTFC_SKETCH_AVX512
  const bool avx512 = simd == 1 && cpu_has_avx512f();
  const bool avx2 = !avx512 && simd != 0 && cpu_has_avx2_fma();
#else
  const bool avx512 = false, avx2 = false;
  (void)simd;
#endif
#pragma omp parallel for schedule(dynamic, 1)
  for (int64_t t = 0; t < tasks; ++t) {
    const size_t j0 = size_t(t) * k_texels, j1 = std::min(n, j0 + k_texels);
#ifdef BTFC_SKETCH_AVX512
    if (avx512) {
      const size_t g = S.s / 16;
      part[size_t(t)] = g == 16   ? sketch_avx512<16>(B, m, S, j0, j1, W, energy != nullptr)
                        : g == 24 ? sketch_avx512<24>(B, m, S, j0, j1, W, energy != nullptr)
                                  : sketch_avx512<0>(B, m, S, j0, j1, W, energy != nullptr);
      continue;
    }
    if (avx2) {
      part[size_t(t)] = sketch_avx2(B, m, S, j0, j1, W, energy != nullptr);
      continue;
    }
#endif
    part[size_t(t)] = sketch_portable(B, m, S, j0, j1, W, energy != nullptr);
  }
  (void)avx512, (void)avx2;
  if (energy) {
    *energy = 0;
    for (double v : part) *energy += v;  // fixed order: independent of the thread count
  }
}

}  // namespace

void sparse_sign_product(const float* B, size_t n, const SparseSign& S, float* W, double* energy) { sketch(B, n, S, W, energy, 1); }

void sparse_sign_product_reference(const float* B, size_t n, const SparseSign& S, float* W, double* energy) {
  sketch(B, n, S, W, energy, 0);
}

bool sparse_sign_product_avx2(const float* B, size_t n, const SparseSign& S, float* W, double* energy) {
#ifdef BTFC_SKETCH_AVX512
  if (!cpu_has_avx2_fma()) return false;
  sketch(B, n, S, W, energy, 2);
  return true;
#else
  (void)B, (void)n, (void)S, (void)W, (void)energy;
  return false;
#endif
}

namespace {
// A parallel task of sparse_sign_columns' bucket order: up to 2048 rows of B and 16 buckets; a
// bucket's sum (8 KB) stays in L1 while its texels' pieces of B (8 KB each) come from memory. In
// texel order a task is a chunk of rows: its s sums sit in L2 / L3 while B's pieces come in
// storage order at a constant stride (0.26 s against 0.35 s for 19683 x 65536 at s = 256, one
// layer, on 2 Zen 3 cores, bench_products; the bucket order's jumps between a bucket's texels are
// what cost). Texel order needs two chunks or more to keep two cores busy, so the bucket order
// stays for calls of fewer than 4096 rows (small matrices, a block's last rows).
constexpr size_t k_column_rows = 2048, k_column_buckets = 16;
// Texel order's chunks: a multiple of 4 (even work on 1, 2 or 4 threads), of equal size (a
// multiple of 16 rows), at most 8192 rows each. Chunks of 2048 rows and a short last one left
// one of 2 threads idle for a third of color=dfmf's sketches (6561 rows: 2048 x 3 + 417), and
// longer pieces of B per texel beat sums nearer the core on a 2-core Xeon (Sapphire Rapids, 2 MB
// L2): one layer over the UBO2003-size matrix 0.373-0.379 s -> 0.314-0.321 s, the dfmf encode's
// three sketches 0.43 -> 0.34 s (docs/benchmarks.md, 2026-12-05). The chunking is the same on
// any thread count, so ||B||^2, summed by chunks, has the same bits too.
constexpr size_t k_texel_chunk_max = 8192;

// acc[0, count) += v or -= v; with `energy`, the squares of v summed into e (in double) in the
// same loop (one read of v: the texel order's pieces come from memory).
BTFC_CPU_CLONES void add_piece(float* acc, const float* v, size_t count, bool negative, bool energy, double& e) {
  if (energy) {
    const float sign = negative ? -1.0f : 1.0f;  // acc + (-1 x) == acc - x: the same bits
    double s = 0;
#pragma omp simd reduction(+ : s)
    for (size_t i = 0; i < count; ++i) {
      const float x = v[i];
      acc[i] += sign * x;
      s += double(x) * double(x);
    }
    e += s;
  } else if (negative) {
#pragma omp simd
    for (size_t i = 0; i < count; ++i) acc[i] -= v[i];
  } else {
#pragma omp simd
    for (size_t i = 0; i < count; ++i) acc[i] += v[i];
  }
}
}  // namespace

void sparse_sign_columns(const float* B, size_t ldb, size_t m, size_t n, const SparseSign& S, float* W, double* energy, size_t first,
                         bool accumulate, size_t segment) {
  // The energy by segments of rows: a piece that crosses a segment's end is added in two calls
  // (the same sums), its squares going to each segment's own total. One segment: as one call.
  const size_t seg = segment ? segment : std::max<size_t>(1, m), nseg = std::max<size_t>(1, (m + seg - 1) / seg);
  auto add = [&](float* acc, const float* piece, size_t i0, size_t rows, bool negative, bool en, double* e) {
    if (!en || nseg == 1) {
      add_piece(acc, piece, rows, negative, en, e[0]);
      return;
    }
    for (size_t a = 0; a < rows;) {
      const size_t k = (i0 + a) / seg, b = std::min(rows, (k + 1) * seg - i0);
      add_piece(acc + a, piece + a, b - a, negative, true, e[k]);
      a = b;
    }
  };
  auto total = [&](const std::vector<double>& part) {  // per segment, the parts in order: independent of the thread count
    for (size_t k = 0; k < nseg; ++k) {
      energy[k] = 0;
      for (size_t p = k; p < part.size(); p += nseg) energy[k] += part[p];
    }
  };
  // Each texel's bucket per layer, from the row groups' picks (only the blocks of row groups
  // that hold texels [first, first + n)). An entry: the bucket (texel order) or the texel from
  // first (bucket order), bit 30 set in its first layer, bit 31 when it enters negated.
  constexpr uint32_t k_first = 1u << 30, k_index = k_first - 1;
  const size_t groups = S.s / 16, q_all = (S.m + 15) / 16, end = first + n;
  std::vector<uint32_t> bucket(S.layers * n);
  for (size_t t = 0; t < S.layers; ++t)
    for (size_t b0 = first / 16 / groups * groups; b0 < (end + 15) / 16; b0 += groups)
      for (size_t k = 0; k < groups && b0 + k < q_all; ++k) {
        const size_t q = b0 + S.pick[t * q_all + b0 + k];
        for (size_t r = 0; r < 16; ++r)
          if (16 * q + r >= first && 16 * q + r < end) bucket[t * n + 16 * q + r - first] = uint32_t(16 * k + r);
      }
  auto flags = [&](size_t j, size_t t) {
    const size_t g = first + j;
    const uint16_t negative = S.negative[t * q_all + g / 16];
    return (uint32_t((negative >> (g % 16)) & 1u) << 31) | (t == 0 ? k_first : 0u);
  };
  if (m >= 2 * k_column_rows) {
    // Texel order: chunks of rows on the threads, every chunk adding the texels in order into
    // its rows of all s sums. A bucket's sum gets its texels in the same order as in bucket
    // order (texel by texel, layer by layer), so W has the same bits either way.
    std::vector<uint32_t> entry(S.layers * n);
    for (size_t j = 0; j < n; ++j)
      for (size_t t = 0; t < S.layers; ++t) entry[j * S.layers + t] = bucket[t * n + j] | flags(j, t);
    const size_t quads = (m + 4 * k_texel_chunk_max - 1) / (4 * k_texel_chunk_max);
    const size_t per = ((m + 4 * quads - 1) / (4 * quads) + 15) / 16 * 16;  // rows per chunk
    const int64_t chunks = int64_t((m + per - 1) / per);
    std::vector<double> part(size_t(chunks) * nseg, 0.0);
#pragma omp parallel for schedule(static, 1)
    for (int64_t chunk = 0; chunk < chunks; ++chunk) {
      const size_t i0 = size_t(chunk) * per, rows = std::min(per, m - i0);
      if (!accumulate)
        for (size_t b = 0; b < S.s; ++b) std::fill_n(W + b * m + i0, rows, 0.0f);
      std::vector<double> e(nseg, 0.0);
      for (size_t j = 0; j < n; ++j) {
        const float* piece = B + j * ldb + i0;
        if (j + 4 < n) {  // the start of the piece four texels ahead (kept with the fused loop, not timed alone)
          __builtin_prefetch(piece + 4 * ldb);
          __builtin_prefetch(piece + 4 * ldb + 16);
        }
        for (size_t t = 0; t < S.layers; ++t) {
          const uint32_t c = entry[j * S.layers + t];
          add(W + size_t(c & k_index) * m + i0, piece, i0, rows, (c >> 31) != 0, energy && (c & k_first), e.data());
        }
      }
      std::copy(e.begin(), e.end(), part.begin() + chunk * int64_t(nseg));
    }
    if (energy) total(part);
    return;
  }
  // Bucket order: each bucket's texels, in texel order and layer by layer; a task sums one
  // bucket at a time in L1.
  std::vector<uint32_t> start(S.s + 1, 0), list(S.layers * n);
  for (uint32_t b : bucket) ++start[b + 1];
  for (size_t b = 0; b < S.s; ++b) start[b + 1] += start[b];
  {
    std::vector<uint32_t> fill(start.begin(), start.end() - 1);
    for (size_t j = 0; j < n; ++j)
      for (size_t t = 0; t < S.layers; ++t) list[fill[bucket[t * n + j]]++] = uint32_t(j) | flags(j, t);
  }
  // Tasks: a block of rows and a range of buckets (the buckets read disjoint texels).
  const size_t row_blocks = (m + k_column_rows - 1) / k_column_rows, ranges = S.s / k_column_buckets;
  const int64_t tasks = int64_t(row_blocks * ranges);
  std::vector<double> part(size_t(tasks) * nseg, 0.0);
#pragma omp parallel for schedule(dynamic, 1)
  for (int64_t task = 0; task < tasks; ++task) {
    const size_t i0 = size_t(task) / ranges * k_column_rows, rows = std::min(k_column_rows, m - i0);
    const size_t b0 = size_t(task) % ranges * k_column_buckets;
    std::vector<double> e(nseg, 0.0);
    for (size_t b = b0; b < b0 + k_column_buckets; ++b) {
      float* acc = W + b * m + i0;
      if (!accumulate) std::fill_n(acc, rows, 0.0f);
      for (uint32_t at = start[b]; at < start[b + 1]; ++at) {
        const uint32_t c = list[at];
        const float* piece = B + size_t(c & k_index) * ldb + i0;
        if (at + 1 < list.size()) {  // the next piece: a jump the hardware prefetcher does not take
          const float* next = B + size_t(list[at + 1] & k_index) * ldb + i0;
          for (size_t i = 0; i < rows; i += 16) __builtin_prefetch(next + i);
        }
        add(acc, piece, i0, rows, (c >> 31) != 0, energy && (c & k_first), e.data());  // squares once: in the first layer
      }
    }
    std::copy(e.begin(), e.end(), part.begin() + task * int64_t(nseg));
  }
  if (energy) total(part);
}

}  // namespace btfc
