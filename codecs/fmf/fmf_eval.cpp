// Random-access evaluation on the CPU: sorted blocks, blended rows (fmf_eval.h).
#include "codecs/fmf/fmf_eval.h"

#include <algorithm>
#include <cstddef>
#include <cstring>
#include <omp.h>
#include <vector>

#include "codecs/fmf/fmf_model.h"
#include "core/cpu_dispatch.h"

namespace btfc::fmf {

namespace {

// 16 floats, any alignment: GCC lowers it to one AVX-512 register in the x86-64-v4 clone, two
// AVX2 registers in the v3 clone and four SSE registers in the baseline (core/cpu_dispatch.h),
// where a plain loop would be vectorized at 256 bits only (GCC's default preferred width).
typedef float v16 __attribute__((vector_size(64), aligned(4), may_alias));
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

// The pair a query leans on most: its largest light and view weights.
inline uint32_t dominant_pair(const btfc_fmf_query& e, int nL) {
  int a = 0, b = 0;
  for (int j = 1; j < 3; ++j) {
    if (e.wl[j] > e.wl[a]) a = j;
    if (e.wv[j] > e.wv[b]) b = j;
  }
  return uint32_t(e.light[a]) + uint32_t(nL) * uint32_t(e.view[b]);
}

// The sorted block's blend with everything in registers, for nc = NC channels of C = 16 PER
// components (each channel's row starts on a vector). All 9 terms are summed, branch-free; a
// term of weight 0 reads `zero` (so a zero weight contributes exactly 0, as the reference's
// skipped term). A query with the previous one's pair reuses the blended rows.
template <int NC, int PER>
__attribute__((always_inline)) inline void blend_sorted(const EvalFactors& f, const Sorted* s, size_t n, float* out,
                                                        const float* zero, size_t ahead) {
  constexpr int V = NC * PER;
  constexpr size_t C = 16 * PER, W = NC * C;
  const size_t nL = size_t(f.nL);
  v16 acc[V];
  const Sorted* prev = nullptr;
  for (size_t j = 0; j < n; ++j) {
    if (j + ahead < n) {
      const float* r = f.SxV + size_t(s[j + ahead].texel) * C;
      for (size_t k = 0; k < C; k += 16) __builtin_prefetch(r + k);
    }
    const Sorted& e = s[j];
    if (!prev || !same_pair(e, *prev)) {
      const float* r[9];
      float w[9];
      for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b) {
          const float wt = e.wl[a] * e.wv[b];
          w[3 * a + b] = wt;
          r[3 * a + b] = wt != 0 ? f.U + (size_t(e.light[a]) + nL * size_t(e.view[b])) * W : zero;
        }
      // Three chains of three (one per light vertex), then their sum: a chain of 9 dependent
      // FMAs would make the query's latency, not the FMA rate, the bound.
      for (int i = 0; i < V; ++i) {
        v16 x0 = w[0] * *(const v16*)(r[0] + 16 * i), x1 = w[3] * *(const v16*)(r[3] + 16 * i), x2 = w[6] * *(const v16*)(r[6] + 16 * i);
        x0 += w[1] * *(const v16*)(r[1] + 16 * i), x1 += w[4] * *(const v16*)(r[4] + 16 * i), x2 += w[7] * *(const v16*)(r[7] + 16 * i);
        x0 += w[2] * *(const v16*)(r[2] + 16 * i), x1 += w[5] * *(const v16*)(r[5] + 16 * i), x2 += w[8] * *(const v16*)(r[8] + 16 * i);
        acc[i] = x0 + x1 + x2;
      }
      prev = &e;
    }
    const float* v = f.SxV + size_t(e.texel) * C;
    float* o = out + j * NC;  // in sorted order: the caller scatters the block's results
    for (int c = 0; c < NC; ++c) {
      v16 d = acc[c * PER] * *(const v16*)v;
      for (int i = 1; i < PER; ++i) d += acc[c * PER + i] * *(const v16*)(v + 16 * i);
      o[c] = hsum(d);
    }
  }
}

}  // namespace

BTFC_CPU_CLONES void eval_weighted_block(const EvalFactors& f, const btfc_fmf_query* q, size_t n, float* out) {
  if (n == 0) return;
  const size_t C = size_t(f.C), nc = size_t(f.nc), width = nc * C;
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
  bool done = false;
#define BTFC_BLEND(NC, PER) \
  if (!done && nc == NC && C == 16 * PER) blend_sorted<NC, PER>(f, sorted.data(), n, res.data(), zero_row, ahead), done = true;
  BTFC_BLEND(3, 1) BTFC_BLEND(3, 2) BTFC_BLEND(3, 3) BTFC_BLEND(3, 4) BTFC_BLEND(3, 5) BTFC_BLEND(3, 8)
  BTFC_BLEND(1, 1) BTFC_BLEND(1, 2) BTFC_BLEND(1, 3) BTFC_BLEND(1, 4) BTFC_BLEND(1, 5) BTFC_BLEND(1, 8)
#undef BTFC_BLEND
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
  for (size_t i = 0; i < n; ++i) {
    const EvalQuery& e = q[i];
    btfc_fmf_query& k = out[i];
    if (i > 0 && e.light < 0 && q[i - 1].light < 0 && std::memcmp(&e.wl, &q[i - 1].wl, sizeof(Vec3)) == 0 &&
        std::memcmp(&e.wv, &q[i - 1].wv, sizeof(Vec3)) == 0) {
      k = out[i - 1];
      k.texel = e.x + m_desc.width * e.y;
      continue;
    }
    k.texel = e.x + m_desc.width * e.y;
    DirWeights a, b;
    if (e.light >= 0) a.index = {e.light, e.light, e.light}, b.index = {e.view, e.view, e.view};
    else a = m_light_interp.weights(e.wl), b = m_view_interp.weights(e.wv);
    for (int j = 0; j < 3; ++j) k.light[j] = a.index[j], k.view[j] = b.index[j], k.wl[j] = a.weight[j], k.wv[j] = b.weight[j];
  }
}

Status FmfModel::eval_batch_cpu(std::span<const EvalQuery> q, float* out) const {
  const Block& blk = m_blocks[0];
  EvalFactors f;
  f.U = blk.U.data(), f.SxV = blk.SxV.data();
  f.C = int(blk.U.cols()), f.nc = m_desc.channels;
  f.nL = int(m_desc.num_lights()), f.nV = int(m_desc.num_views());
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
