// Random-access evaluation on the CPU: sorted blocks, blended rows (fmf_eval.h).
#include "codecs/fmf/fmf_eval.h"

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <cstring>
#include <omp.h>
#include <vector>

#include <Imath/half.h>

#include "codecs/fmf/fmf_model.h"
#include "core/cpu_dispatch.h"
#include "core/memory.h"
#if BTFC_CPU_DISPATCH
#include <immintrin.h>
#endif

namespace btfc::fmf {

namespace {

// 16 floats, any alignment: GCC lowers it to one AVX-512 register in the x86-64-v4 clone, two
// AVX2 registers in the v3 clone and four SSE registers in the baseline (core/cpu_dispatch.h),
// where a plain loop would be vectorized at 256 bits only (GCC's default preferred width).
typedef float v16 __attribute__((vector_size(64), aligned(4), may_alias));
// The helpers below take and return these vectors by value: always inlined, they cross no ABI,
// so the compilers' note on the baseline's vector ABI (-Wpsabi) does not apply.
#pragma GCC diagnostic ignored "-Wpsabi"
typedef float v8 __attribute__((vector_size(32), aligned(4), may_alias));
typedef float v4 __attribute__((vector_size(16), aligned(4), may_alias));

__attribute__((always_inline)) inline float hsum(v16 v) {
  v8 s8 = __builtin_shufflevector(v, v, 0, 1, 2, 3, 4, 5, 6, 7) + __builtin_shufflevector(v, v, 8, 9, 10, 11, 12, 13, 14, 15);
  v4 s4 = __builtin_shufflevector(s8, s8, 0, 1, 2, 3) + __builtin_shufflevector(s8, s8, 4, 5, 6, 7);
  return (s4[0] + s4[2]) + (s4[1] + s4[3]);
}

// acc[0, n) (+)= w * row[0, n)
__attribute__((always_inline)) inline void axpy(float* acc, const float* row, float w, size_t n, bool first) {
  size_t k = 0;
  if (first) {
    for (; k + 16 <= n; k += 16) *(v16*)(acc + k) = w * *(const v16*)(row + k);
    for (; k < n; ++k) acc[k] = w * row[k];
  } else {
    for (; k + 16 <= n; k += 16) *(v16*)(acc + k) += w * *(const v16*)(row + k);
    for (; k < n; ++k) acc[k] += w * row[k];
  }
}

__attribute__((always_inline)) inline float dot(const float* a, const float* b, size_t n) {
  v16 s = {};
  size_t k = 0;
  for (; k + 16 <= n; k += 16) s += *(const v16*)(a + k) * *(const v16*)(b + k);
  float r = hsum(s);
  for (; k < n; ++k) r += a[k] * b[k];
  return r;
}

// A query in the sorted block: what the blend reads, sequentially, and where its result goes.
struct Sorted {
  uint32_t texel, orig;
  uint16_t light[3], view[3];
  float wl[3], wv[3];
};
static_assert(sizeof(Sorted) == 44);

inline bool same_pair(const Sorted& a, const Sorted& b) {
  return std::memcmp(&a.light, &b.light, sizeof(Sorted) - offsetof(Sorted, light)) == 0;
}
[[maybe_unused]] inline bool same_pair(const btfc_fmf_query& a, const btfc_fmf_query& b) {  // blend_half_avx512's
  return std::memcmp(&a.light, &b.light, sizeof(btfc_fmf_query) - offsetof(btfc_fmf_query, light)) == 0;
}

// The pair a query leans on most: its largest light and view weights.
inline uint32_t dominant_pair(const btfc_fmf_query& e, int nL) {
  int a = 0, b = 0;
  for (int j = 1; j < 3; ++j) {
    if (e.wl[j] > e.wl[a]) a = j;
    if (e.wv[j] > e.wv[b]) b = j;
  }
  return uint32_t(e.light[a]) + uint32_t(nL) * uint32_t(e.view[b]);
}

// The 9 (row, weight) terms of a query's blend: row (light a, view b) of `U` (W values per
// pair; U's floats or halves) with weight wl[a] wv[b], or `zero` for a term of weight 0. Q is a
// sorted query or a btfc_fmf_query.
template <class Q, class T>
__attribute__((always_inline)) inline void pair_rows(const Q& e, const T* U, int nL, size_t W, const T* zero, const T* r[9], float w[9]) {
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) {
      const float wt = e.wl[a] * e.wv[b];
      w[3 * a + b] = wt;
      r[3 * a + b] = wt != 0 ? U + (size_t(e.light[a]) + size_t(nL) * size_t(e.view[b])) * W : zero;
    }
}

// The texel row (C floats) of the query `ahead` after j, prefetched.
template <class Q>
__attribute__((always_inline)) inline void prefetch_texel(const EvalFactors& f, const Q* s, size_t j, size_t n, size_t ahead, size_t C) {
  if (j + ahead >= n) return;
  const float* r = f.SxV + size_t(s[j + ahead].texel) * C;
  for (size_t k = 0; k < C; k += 16) __builtin_prefetch(r + k);
}

// A row's 16 values as floats: U's own, or its halves converted (exact; vcvtph2ps in the
// AVX-512 kernel that alone reads halves, blend_half_avx512).
__attribute__((always_inline)) inline v16 load_row(const float* p) { return *(const v16*)p; }
#if BTFC_CPU_DISPATCH
__attribute__((target("avx512f,f16c"))) inline v16 load_row(const uint16_t* p) {
  return (v16)_mm512_maskz_cvtph_ps(0xffff, _mm256_loadu_si256(reinterpret_cast<const __m256i*>(p)));
}
#endif

// A block's blend with everything in registers, for nc = NC channels of C = 16 PER components
// (each channel's row starts on a vector), from U's rows as floats or halves (T). All 9 terms
// are summed, branch-free; a term of weight 0 reads `zero` (so a zero weight contributes exactly
// 0, as the reference's skipped term). A query with the previous one's pair reuses the blended
// rows. out[j NC + c] in the block's order (a sorted block's: the caller scatters them back).
template <int NC, int PER, class Q, class T>
__attribute__((always_inline)) inline void blend_rows(const EvalFactors& f, const Q* s, size_t n, float* out, const T* U,
                                                      const T* zero, size_t ahead) {
  constexpr int V = NC * PER;
  constexpr size_t C = 16 * PER, W = NC * C;
  v16 acc[V];
  const Q* prev = nullptr;
  for (size_t j = 0; j < n; ++j) {
    prefetch_texel(f, s, j, n, ahead, C);
    const Q& e = s[j];
    if (!prev || !same_pair(e, *prev)) {
      const T* r[9];
      float w[9];
      pair_rows(e, U, f.nL, W, zero, r, w);
      // Three chains of three (one per light vertex), then their sum: a chain of 9 dependent
      // FMAs would make the query's latency, not the FMA rate, the bound.
      for (int i = 0; i < V; ++i) {
        v16 x0 = w[0] * load_row(r[0] + 16 * i), x1 = w[3] * load_row(r[3] + 16 * i), x2 = w[6] * load_row(r[6] + 16 * i);
        x0 += w[1] * load_row(r[1] + 16 * i), x1 += w[4] * load_row(r[4] + 16 * i), x2 += w[7] * load_row(r[7] + 16 * i);
        x0 += w[2] * load_row(r[2] + 16 * i), x1 += w[5] * load_row(r[5] + 16 * i), x2 += w[8] * load_row(r[8] + 16 * i);
        acc[i] = x0 + x1 + x2;
      }
      prev = &e;
    }
    const float* v = f.SxV + size_t(e.texel) * C;
    float* o = out + j * NC;
    for (int c = 0; c < NC; ++c) {
      v16 d = acc[c * PER] * *(const v16*)v;
      for (int i = 1; i < PER; ++i) d += acc[c * PER + i] * *(const v16*)(v + 16 * i);
      o[c] = hsum(d);
    }
  }
}

// The sorted block's blend from U's floats (inlined into eval_weighted_block's CPU clones).
template <int NC, int PER>
__attribute__((always_inline)) inline void blend_sorted(const EvalFactors& f, const Sorted* s, size_t n, float* out,
                                                        const float* zero, size_t ahead) {
  blend_rows<NC, PER>(f, s, n, out, f.U, zero, ahead);
}

#if BTFC_CPU_DISPATCH
// The same blend written for AVX2 + FMA (8 lanes, 16 registers): the v16 code above compiled for
// x86-64-v3 keeps its 6 x 2 accumulators, 9 weights and 3 chains in 16 ymm registers only by
// spilling, and its horizontal sums go through the stack (3.1 M evals/s on a Zen 3 VM against
// 17.3 on Zen 5 with AVX-512; docs/benchmarks.md). Here the blended rows go to an L1 buffer
// slice by slice (9 weights + 3 chains live), the dot keeps the texel's row in S8 registers,
// and the 3 channels' sums are reduced together. C = 8 * S8 components per channel.
template <int NC, int S8>
__attribute__((target("avx2,fma"))) void blend_sorted_avx2(const EvalFactors& f, const Sorted* s, size_t n, float* out,
                                                          const float* zero, size_t ahead) {
  constexpr int V = NC * S8;
  constexpr size_t C = 8 * S8, W = NC * C;
  alignas(32) float acc[V * 8];
  alignas(16) float tail[4];
  const Sorted* prev = nullptr;
  for (size_t j = 0; j < n; ++j) {
    prefetch_texel(f, s, j, n, ahead, C);
    const Sorted& e = s[j];
    if (!prev || !same_pair(e, *prev)) {
      const float* r[9];
      float ws[9];
      pair_rows(e, f.U, f.nL, W, zero, r, ws);
      __m256 w[9];
      for (int i = 0; i < 9; ++i) w[i] = _mm256_set1_ps(ws[i]);
      for (int i = 0; i < V; ++i) {  // three chains of three, as the v16 kernel
        __m256 x0 = _mm256_mul_ps(w[0], _mm256_loadu_ps(r[0] + 8 * i));
        __m256 x1 = _mm256_mul_ps(w[3], _mm256_loadu_ps(r[3] + 8 * i));
        __m256 x2 = _mm256_mul_ps(w[6], _mm256_loadu_ps(r[6] + 8 * i));
        x0 = _mm256_fmadd_ps(w[1], _mm256_loadu_ps(r[1] + 8 * i), x0);
        x1 = _mm256_fmadd_ps(w[4], _mm256_loadu_ps(r[4] + 8 * i), x1);
        x2 = _mm256_fmadd_ps(w[7], _mm256_loadu_ps(r[7] + 8 * i), x2);
        x0 = _mm256_fmadd_ps(w[2], _mm256_loadu_ps(r[2] + 8 * i), x0);
        x1 = _mm256_fmadd_ps(w[5], _mm256_loadu_ps(r[5] + 8 * i), x1);
        x2 = _mm256_fmadd_ps(w[8], _mm256_loadu_ps(r[8] + 8 * i), x2);
        _mm256_store_ps(acc + 8 * i, _mm256_add_ps(_mm256_add_ps(x0, x1), x2));
      }
      prev = &e;
    }
    const float* v = f.SxV + size_t(e.texel) * C;
    __m256 sv[S8];
    for (int i = 0; i < S8; ++i) sv[i] = _mm256_loadu_ps(v + 8 * i);
    __m256 d[4];
    for (int c = 0; c < NC; ++c) {
      d[c] = _mm256_mul_ps(_mm256_load_ps(acc + 8 * (c * S8)), sv[0]);
      for (int i = 1; i < S8; ++i) d[c] = _mm256_fmadd_ps(_mm256_load_ps(acc + 8 * (c * S8 + i)), sv[i], d[c]);
    }
    for (int c = NC; c < 4; ++c) d[c] = _mm256_setzero_ps();
    // [d0 d1 d2 d3] -> 4 sums in one xmm: two rounds of hadd, then the two 128-bit halves.
    const __m256 h = _mm256_hadd_ps(_mm256_hadd_ps(d[0], d[1]), _mm256_hadd_ps(d[2], d[3]));
    _mm_store_ps(tail, _mm_add_ps(_mm256_castps256_ps128(h), _mm256_extractf128_ps(h, 1)));
    for (int c = 0; c < NC; ++c) out[j * NC + c] = tail[c];
  }
}

// The AVX-512 blend reading U as half floats (EvalFactors::Uh, set when every value of U is a
// half, as precision=half models store it: the converted rows are U's own floats, so the result
// is the float kernel's). Random queries read 27 rows of U each; as halves U takes 1.27 MB for
// UBO2003 at rank 32 and stays in a 2 MB L2, where the float copy (2.5 MB) spills to L3. The
// queries in their own order (no sort: with U in L2 it cost what it saved).
template <int NC, int PER>
__attribute__((target("avx512f,fma,f16c"))) void blend_half_avx512(const EvalFactors& f, const btfc_fmf_query* s, size_t n, float* out,
                                                                   const uint16_t* zero, size_t ahead) {
  blend_rows<NC, PER>(f, s, n, out, f.Uh, zero, ahead);
}
#endif

std::atomic<EvalPath> g_path{EvalPath::best};

}  // namespace

BTFC_CPU_CLONES void eval_weighted_block(const EvalFactors& f, const btfc_fmf_query* q, size_t n, float* out) {
  if (n == 0) return;
  const size_t C = size_t(f.C), nc = size_t(f.nc), width = nc * C;
#if BTFC_CPU_DISPATCH
  if (f.Uh && g_path.load(std::memory_order_relaxed) == EvalPath::best && cpu_has_avx512f()) {
    static const uint16_t zero_half[16 * 8 * 3] = {};
    bool done = false;
#define BTFC_BLENDH(NC, PER) \
  if (!done && nc == NC && C == 16 * PER) blend_half_avx512<NC, PER>(f, q, n, out, zero_half, 16), done = true;
    BTFC_BLENDH(3, 1) BTFC_BLENDH(3, 2) BTFC_BLENDH(3, 3) BTFC_BLENDH(3, 4) BTFC_BLENDH(3, 5) BTFC_BLENDH(3, 8)
    BTFC_BLENDH(1, 1) BTFC_BLENDH(1, 2) BTFC_BLENDH(1, 3) BTFC_BLENDH(1, 4) BTFC_BLENDH(1, 5) BTFC_BLENDH(1, 8)
#undef BTFC_BLENDH
    if (done) return;
  }
#endif
  // Counting sort of the block by dominant pair, into at most 8192 buckets (pairs merged in
  // runs of consecutive indices when there are more: neighbours share rows anyway). The
  // queries are moved, not indexed: the blend below then reads them in one sequential stream.
  // (Tiles of texels and view groups as an outer key, to keep the texel rows in L2 too, were
  // slower: docs/benchmarks.md.)
  const uint32_t pairs = uint32_t(f.nL) * uint32_t(f.nV);
  const uint32_t shift = pairs > 8192 ? uint32_t(32 - __builtin_clz((pairs - 1) >> 13)) : 0;
  const uint32_t buckets = ((pairs - 1) >> shift) + 1;
  constexpr size_t ahead = 16;  // prefetch distance (queries) of the texel rows
  // Per thread, kept between calls: fresh memory is slow to fault in on the VMs btfc runs on.
  thread_local std::vector<uint32_t> count, key;
  thread_local std::vector<Sorted> sorted;
  thread_local std::vector<float> acc, res;
  if (key.size() < n) key.resize(n), sorted.resize(n);
  if (res.size() < n * nc) res.resize(n * nc);
  acc.resize(width);
  count.assign(buckets + 1, 0);
  for (size_t i = 0; i < n; ++i) ++count[(key[i] = dominant_pair(q[i], f.nL) >> shift) + 1];
  for (uint32_t b = 0; b < buckets; ++b) count[b + 1] += count[b];
  for (size_t i = 0; i < n; ++i) {
    const btfc_fmf_query& e = q[i];
    Sorted& s = sorted[count[key[i]]++];
    s.texel = uint32_t(e.texel), s.orig = uint32_t(i);
    for (int j = 0; j < 3; ++j) s.light[j] = uint16_t(e.light[j]), s.view[j] = uint16_t(e.view[j]), s.wl[j] = e.wl[j], s.wv[j] = e.wv[j];
  }

  // The blend writes its results in sorted order (a scattered store per query stalls on its
  // cache line), then they are put back in the queries' order. Register-blocked kernels for the
  // common shapes (rgb or grey, ranks 16, 32, 48, 64, 80, 128) are called directly so that each
  // is inlined into this function's CPU clone; other shapes take the generic loop.
  static const float zero_row[16 * 8 * 3] = {};
  const EvalPath path = g_path.load(std::memory_order_relaxed);
  bool done = false;  // a register kernel ran; else the generic loop below
  if (path != EvalPath::generic) {
#if BTFC_CPU_DISPATCH
  if (path == EvalPath::avx2 || (path == EvalPath::best && !cpu_has_avx512f() && cpu_has_avx2_fma())) {
#define BTFC_BLEND2(NC, S8) \
  if (!done && nc == NC && C == 8 * S8) blend_sorted_avx2<NC, S8>(f, sorted.data(), n, res.data(), zero_row, ahead), done = true;
    BTFC_BLEND2(3, 1) BTFC_BLEND2(3, 2) BTFC_BLEND2(3, 4) BTFC_BLEND2(3, 6) BTFC_BLEND2(3, 8) BTFC_BLEND2(3, 10)
    BTFC_BLEND2(1, 1) BTFC_BLEND2(1, 2) BTFC_BLEND2(1, 4) BTFC_BLEND2(1, 6) BTFC_BLEND2(1, 8) BTFC_BLEND2(1, 10)
#undef BTFC_BLEND2
  }
#endif
#define BTFC_BLEND(NC, PER) \
  if (!done && nc == NC && C == 16 * PER) blend_sorted<NC, PER>(f, sorted.data(), n, res.data(), zero_row, ahead), done = true;
  BTFC_BLEND(3, 1) BTFC_BLEND(3, 2) BTFC_BLEND(3, 3) BTFC_BLEND(3, 4) BTFC_BLEND(3, 5) BTFC_BLEND(3, 8)
  BTFC_BLEND(1, 1) BTFC_BLEND(1, 2) BTFC_BLEND(1, 3) BTFC_BLEND(1, 4) BTFC_BLEND(1, 5) BTFC_BLEND(1, 8)
#undef BTFC_BLEND
  }
  const Sorted* prev = nullptr;
  bool any = false;
  for (size_t j = 0; j < n && !done; ++j) {
    const Sorted& e = sorted[j];
    if (!prev || !same_pair(e, *prev)) {
      any = false;
      for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b) {
          const float wt = e.wl[a] * e.wv[b];
          if (wt == 0) continue;
          axpy(acc.data(), f.U + (size_t(e.light[a]) + size_t(f.nL) * size_t(e.view[b])) * width, wt, width, !any);
          any = true;
        }
      if (!any) std::fill(acc.begin(), acc.end(), 0.0f);  // all weights 0
      prev = &e;
    }
    const float* v = f.SxV + size_t(e.texel) * C;
    for (size_t c = 0; c < nc; ++c) res[j * nc + c] = dot(acc.data() + c * C, v, C);
  }
  for (size_t j = 0; j < n; ++j)
    for (size_t c = 0; c < nc; ++c) out[size_t(sorted[j].orig) * nc + c] = res[j * nc + c];
}

bool set_eval_path(EvalPath path) {
  if (path == EvalPath::avx2 && !cpu_has_avx2_fma()) return false;
  g_path.store(path, std::memory_order_relaxed);
  return true;
}

// Queries per block for a batch of n: k_eval_block, or fewer so that every thread gets one.
static size_t block_for(size_t n) {
  const size_t threads = omp_in_parallel() ? 1 : size_t(std::max(1, omp_get_max_threads()));
  return std::clamp<size_t>((n + threads - 1) / threads, 1, k_eval_block);
}

void eval_weighted(const EvalFactors& f, std::span<const btfc_fmf_query> q, float* out) {
  const size_t block = block_for(q.size()), nb = (q.size() + block - 1) / block;
#pragma omp parallel for schedule(dynamic, 1)
  for (size_t b = 0; b < nb; ++b) {
    const size_t b0 = b * block, n = std::min(block, q.size() - b0);
    eval_weighted_block(f, q.data() + b0, n, out + b0 * size_t(f.nc));
  }
}

}  // namespace btfc::fmf

// ---- FmfModel's CPU path (fmf_model.h) ---------------------------------------------------------

namespace btfc::fmf {

void FmfModel::to_weighted(const EvalQuery* q, size_t n, btfc_fmf_query* out) const {
  // In groups: the directions that need a Delaunay lookup are collected and located together
  // (DirectionInterpolator::weights_batch, the same bits as weights()); a query with its
  // predecessor's directions copies its weights afterwards, in order.
  constexpr size_t G = 256;
  Vec3 dl[G], dv[G];
  DirWeights wa[G], wb[G];
  uint32_t who[G];
  bool copy[G];
  for (size_t i0 = 0; i0 < n; i0 += G) {
    const size_t m = std::min(G, n - i0);
    size_t k = 0;
    for (size_t j = 0; j < m; ++j) {
      const size_t i = i0 + j;
      const EvalQuery& e = q[i];
      btfc_fmf_query& o = out[i];
      o.texel = e.x + m_desc.width * e.y;
      copy[j] = false;
      if (e.light >= 0) {
        for (int a = 0; a < 3; ++a) o.light[a] = e.light, o.view[a] = e.view, o.wl[a] = a == 0, o.wv[a] = a == 0;
      } else if (i > 0 && q[i - 1].light < 0 && std::memcmp(&e.wl, &q[i - 1].wl, sizeof(Vec3)) == 0 &&
                 std::memcmp(&e.wv, &q[i - 1].wv, sizeof(Vec3)) == 0) {
        copy[j] = true;
      } else {
        dl[k] = e.wl, dv[k] = e.wv, who[k++] = uint32_t(j);
      }
    }
    m_light_interp.weights_batch(dl, k, wa);
    m_view_interp.weights_batch(dv, k, wb);
    for (size_t j = 0; j < k; ++j) {
      btfc_fmf_query& o = out[i0 + who[j]];
      for (int a = 0; a < 3; ++a) o.light[a] = wa[j].index[a], o.view[a] = wb[j].index[a], o.wl[a] = wa[j].weight[a], o.wv[a] = wb[j].weight[a];
    }
    for (size_t j = 0; j < m; ++j)
      if (copy[j]) {
        const size_t i = i0 + j;
        const int texel = out[i].texel;
        out[i] = out[i - 1];
        out[i].texel = texel;
      }
  }
}

EvalFactors FmfModel::eval_factors() const {
  const Block& blk = m_blocks[0];
  const size_t nu = size_t(blk.U.size()), ns = size_t(blk.SxV.size());
  // SxV starts on the huge page after U's last: neither matrix shares a page with the other.
  constexpr size_t huge = (size_t(2) << 20) / sizeof(float);
  const size_t off = (nu + huge - 1) / huge * huge, off_h = off + (ns + huge - 1) / huge * huge;
  std::call_once(m_eval_once, [&] {
    // U as halves too when every value is one (precision=half models; blend_half_avx512).
    bool halves = true;
    for (size_t i = 0; i < nu && halves; ++i) halves = float(Imath::half(blk.U.data()[i])) == blk.U.data()[i];
    const size_t total = off_h + (halves ? (nu + 1) / 2 : 0);
    float* p = static_cast<float*>(page_alloc(total * sizeof(float)));
    m_eval_copy.reset(p, PageFree{});
    std::copy(blk.U.data(), blk.U.data() + nu, p);
    std::copy(blk.SxV.data(), blk.SxV.data() + ns, p + off);
    if (halves) {
      uint16_t* h = reinterpret_cast<uint16_t*>(p + off_h);
      for (size_t i = 0; i < nu; ++i) h[i] = Imath::half(blk.U.data()[i]).bits();
      m_eval_half = h;
    }
  });
  EvalFactors f;
  f.U = m_eval_copy.get(), f.SxV = m_eval_copy.get() + off, f.Uh = m_eval_half;
  f.C = int(blk.U.cols()), f.nc = m_desc.channels;
  f.nL = int(m_desc.num_lights()), f.nV = int(m_desc.num_views());
  return f;
}

Status FmfModel::eval_batch_cpu(std::span<const EvalQuery> q, float* out) const {
  if (q.empty()) return {};  // no copy of the factors for nothing
  const EvalFactors f = eval_factors();
  const size_t block = block_for(q.size()), nb = (q.size() + block - 1) / block;
#pragma omp parallel
  {
    thread_local std::vector<btfc_fmf_query> kq;  // kept, as the sorted block's buffers
    if (kq.size() < block) kq.resize(block);
#pragma omp for schedule(dynamic, 1)
    for (size_t b = 0; b < nb; ++b) {
      const size_t b0 = b * block, n = std::min(block, q.size() - b0);
      to_weighted(q.data() + b0, n, kq.data());
      eval_weighted_block(f, kq.data(), n, out + b0 * size_t(f.nc));
    }
  }
  return {};
}

}  // namespace btfc::fmf
