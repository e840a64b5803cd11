// Random-access evaluation of color=dfmf models on the CPU (issue 24): FmfModel::eval_batch's
// path for Bonn's DFMF colour model when no GPU is used.
//
// A dfmf value is not linear in the factors (Y = exp(log Y) per measured pair), so the rgb path's
// blended rows (fmf_eval.h) do not apply: each of a query's 9 (light, view) pairs is evaluated
// (3 dots: log Y', U', V' rows against the texel's rows), turned into RGB and blended with the
// pair's weight, in eval_dir's (a, b) order. What this path saves over the per-query reference
// (Model::eval_batch -> eval_dir -> 9 x eval): the two Delaunay lookups run in groups
// (to_weighted, as the rgb path: weights_batch, the same bits); the three blocks are copied once
// into one interleaved, padded layout (DfmfFactors), so a texel's or a pair's rows are one run;
// per channel the 9 dots run at once (9 vector accumulators, summed across lanes together); the
// 9 exponentials are a branch-free polynomial (exp_poly) instead of libm calls; the next texel
// rows are prefetched.
//
// Contract: out equals eval_dir's result to float rounding (another summation order in the dots,
// exp_poly within a few ulp of std::exp); the tests assert a relative error <= 1e-5 against it.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <omp.h>
#include <vector>

#include "codecs/fmf/fmf_model.h"
#include "core/cpu_dispatch.h"
#include "core/memory.h"

namespace btfc::fmf {

namespace {

// e^x in float: x = n ln2 + r, |r| <= ln2 / 2, a degree-6 Taylor polynomial of e^r (Horner;
// relative error < 2e-7 on that range), times 2^n built in the exponent bits. Branch-free and
// without float-to-int conversions (n is rounded by the 1.5 x 2^23 shift, its integer read from
// the mantissa), so a loop over it vectorizes and a NaN stays a NaN without undefined behaviour.
// Beyond float's range: +inf above 88.72 (as std::exp), 0 below -87.34 (std::exp gives a
// subnormal there; the decoded Y is -offset either way to float rounding).
inline float exp_poly(float x) {
  const float hi = 88.7228f, lo = -87.3365f;
  float xc = x < lo ? lo : x;
  xc = xc > hi ? hi : xc;
  const float t = xc * 1.44269504f + 12582912.f;
  const float n = t - 12582912.f;
  int32_t ti;
  std::memcpy(&ti, &t, 4);
  const int32_t ni = ti - 0x4B400000;  // n, -126..128 for finite x
  // ln 2 in two parts (Cody-Waite), so r keeps its low bits.
  const float r = (xc - n * 0.693145752f) - n * 1.42860677e-6f;
  float p = 1.f / 720;
  p = p * r + 1.f / 120;
  p = p * r + 1.f / 24;
  p = p * r + 1.f / 6;
  p = p * r + 0.5f;
  p = p * r + 1.f;
  p = p * r + 1.f;
  // 2^n: n + 127 in the exponent field; n = 128 (x near 88.72) as 2 x 2^127.
  const int32_t e = ni > 127 ? 127 : ni;
  const uint32_t bits = uint32_t(e + 127) << 23;
  float two_n;
  std::memcpy(&two_n, &bits, 4);
  float y = p * two_n * (ni > 127 ? 2.f : 1.f);
  y = x > hi ? HUGE_VALF : y;
  return x < lo ? 0.f : y;
}

// The helpers below take and return vectors by value: always inlined, they cross no ABI, so
// GCC's note on the baseline clone's vector ABI does not apply.
#pragma GCC diagnostic ignored "-Wpsabi"

// 8 floats, any alignment (fmf_eval.cpp's v8): one AVX2 register in the v3 and v4 clones, two
// SSE registers in the baseline.
typedef float v8 __attribute__((vector_size(32), aligned(4), may_alias));

// [a0 + a1, a2 + a3, b0 + b1, b2 + b3, a4 + a5, a6 + a7, b4 + b5, b6 + b7] (vhaddps).
__attribute__((always_inline)) inline v8 hadd(v8 a, v8 b) {
  return __builtin_shufflevector(a, b, 0, 2, 8, 10, 4, 6, 12, 14) + __builtin_shufflevector(a, b, 1, 3, 9, 11, 5, 7, 13, 15);
}
// Lane p = the sum of a[p]'s lanes, for p < 8.
__attribute__((always_inline)) inline v8 sum8(const v8* a) {
  const v8 u0 = hadd(hadd(a[0], a[1]), hadd(a[2], a[3])), u1 = hadd(hadd(a[4], a[5]), hadd(a[6], a[7]));
  return __builtin_shufflevector(u0, u1, 0, 1, 2, 3, 8, 9, 10, 11) + __builtin_shufflevector(u0, u1, 4, 5, 6, 7, 12, 13, 14, 15);
}
__attribute__((always_inline)) inline float hsum(v8 a) {
  return ((a[0] + a[4]) + (a[1] + a[5])) + ((a[2] + a[6]) + (a[3] + a[7]));
}

// The three channel blocks interleaved and padded: row r of U holds the Y', U', V' components
// back to back, channel k at off[k], each zero-padded to P[k] = C[k] rounded up to 8 (Ct = the
// sum), and so does a texel's row of SxV. A pair's or a texel's rows are then one contiguous run
// (adjacent lines, one page) instead of three scattered ones, and the dots need no tail (the
// pads add 0 x 0). On transparent huge pages (FmfModel::eval_factors' reasoning: the TLB).
struct DfmfFactors {
  const float* U = nullptr;  // [nL nV][Ct], row = l + nL v
  const float* S = nullptr;  // [texels][Ct]
  int C[3] = {0, 0, 0}, P[3] = {0, 0, 0}, off[3] = {0, 0, 0};
  int Ct = 0, nL = 0, nV = 0;
  float offset = 0;
};

BTFC_CPU_CLONES void blend_dfmf(const DfmfFactors& f, const btfc_fmf_query* q, size_t n, float* out) {
  for (size_t i = 0; i < n; ++i) {
    // The texel row of the query 4 ahead: it is the one row a random query surely misses in
    // cache (SxV is 25 MB for UBO2003 at rank 32). 9.5 -> 12.0 M evals/s on 2 cores (bench_eval
    // --color dfmf, docs/benchmarks.md); prefetching the pairs' rows as well was slower.
    if (i + 4 < n) {
      const char* t = reinterpret_cast<const char*>(f.S + size_t(q[i + 4].texel) * size_t(f.Ct));
      for (int b = 0; b < f.Ct * 4; b += 64) __builtin_prefetch(t + b);
    }
    const btfc_fmf_query& e = q[i];
    const float* s = f.S + size_t(e.texel) * size_t(f.Ct);
    // The 9 pairs' rows, in eval_dir's (a, b) order; a pair of weight 0 is evaluated too (its
    // indices clamped into range) and left out of the blend below.
    const float* row[9];
    float w[9];
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) {
        const int l = std::clamp(e.light[a], 0, f.nL - 1), v = std::clamp(e.view[b], 0, f.nV - 1);
        row[3 * a + b] = f.U + (size_t(l) + size_t(f.nL) * size_t(v)) * size_t(f.Ct);
        w[3 * a + b] = e.wl[a] * e.wv[b];
      }
    // Per channel, the 9 dots at once: 9 accumulators over the texel's row, 8 of them summed
    // across lanes together (sum8), the 9th alone.
    float dots[3][9];
    for (int k = 0; k < 3; ++k) {
      v8 acc[9];
      for (int p = 0; p < 9; ++p) acc[p] = v8{0, 0, 0, 0, 0, 0, 0, 0};
      for (int j = f.off[k]; j < f.off[k] + f.P[k]; j += 8) {
        const v8 sv = *(const v8*)(s + j);
        for (int p = 0; p < 9; ++p) acc[p] += *(const v8*)(row[p] + j) * sv;
      }
      const v8 d = sum8(acc);
      for (int p = 0; p < 8; ++p) dots[k][p] = d[p];
      dots[k][8] = hsum(acc[8]);
    }
    float ex[9];
    for (int p = 0; p < 9; ++p) ex[p] = exp_poly(dots[0][p]);
    // FmfModel::undecorrelate per pair (dfmf_rgb), then the blend: acc += w * rgb, in the pairs' order.
    float acc[3] = {0, 0, 0};
    for (int p = 0; p < 9; ++p) {
      if (w[p] == 0) continue;
      float rgb[3];
      dfmf_rgb(ex[p], dots[1][p], dots[2][p], f.offset, rgb);
      for (int c = 0; c < 3; ++c) acc[c] += w[p] * rgb[c];
    }
    for (int c = 0; c < 3; ++c) out[3 * i + c] = acc[c];
  }
}

}  // namespace

Status FmfModel::eval_batch_dfmf_cpu(std::span<const EvalQuery> q, float* out) const {
  if (q.empty()) return {};  // no copy of the factors for nothing
  DfmfFactors f;
  for (int k = 0; k < 3; ++k) {
    f.C[k] = int(m_blocks[size_t(k)].U.cols());
    f.P[k] = (f.C[k] + 7) / 8 * 8;
    f.off[k] = f.Ct;
    f.Ct += f.P[k];
  }
  f.nL = int(m_desc.num_lights()), f.nV = int(m_desc.num_views());
  f.offset = m_cfg.offset;
  const size_t rows = size_t(m_blocks[0].U.rows()), texels = size_t(m_blocks[0].SxV.rows()), ct = size_t(f.Ct);
  // SxV starts on the huge page after U's last. Made once, on the first call, and kept, as the
  // rgb path's eval_factors() copy (the factors' size once more, only when eval_batch runs here).
  constexpr size_t huge = (size_t(2) << 20) / sizeof(float);
  const size_t s_off = (rows * ct + huge - 1) / huge * huge;
  std::call_once(m_dfmf_once, [&] {
    float* p = static_cast<float*>(page_alloc((s_off + texels * ct) * sizeof(float)));
    m_dfmf_copy.reset(p, PageFree{});
    std::fill_n(p, rows * ct, 0.0f);
    std::fill_n(p + s_off, texels * ct, 0.0f);
    for (int k = 0; k < 3; ++k) {
      const Block& b = m_blocks[size_t(k)];
      const size_t c = size_t(f.C[k]), o = size_t(f.off[k]);
      for (size_t r = 0; r < rows; ++r) std::copy_n(b.U.data() + r * c, c, p + r * ct + o);
      for (size_t t = 0; t < texels; ++t) std::copy_n(b.SxV.data() + t * c, c, p + s_off + t * ct + o);
    }
  });
  f.U = m_dfmf_copy.get();
  f.S = m_dfmf_copy.get() + s_off;
  constexpr size_t k_block = 4096;
  const size_t nb = (q.size() + k_block - 1) / k_block;
#pragma omp parallel
  {
    std::vector<btfc_fmf_query> kq(std::min(k_block, q.size()));
#pragma omp for schedule(dynamic, 1)
    for (size_t b = 0; b < nb; ++b) {
      const size_t b0 = b * k_block, n = std::min(k_block, q.size() - b0);
      to_weighted(q.data() + b0, n, kq.data());
      blend_dfmf(f, kq.data(), n, out + 3 * b0);
    }
  }
  return {};
}

}  // namespace btfc::fmf
