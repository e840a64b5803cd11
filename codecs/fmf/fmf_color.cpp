// fmf's colour transforms (fmf_model.h): dfmf's log-luminance / chroma channels with their
// offset, Bonn's colour models for factorizations read from Bonn files, and those
// factorizations as models (make_fmf_model, fmf.h).
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <limits>

#include "codecs/fmf/fmf_model.h"
#include "core/cpu_dispatch.h"

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#endif

namespace btfc {
namespace fmf {
namespace {

struct YuvFromRgb {
  float m[3][3];
  YuvFromRgb() {
    double a[3][3];
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) a[i][j] = k_rgb_from_yuv[i][j];
    const double det = a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1]) - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0]) +
                       a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]);
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) {  // adjugate / det
        const int r0 = (j + 1) % 3, r1 = (j + 2) % 3, c0 = (i + 1) % 3, c1 = (i + 2) % 3;
        m[i][j] = float((a[r0][c0] * a[r1][c1] - a[r0][c1] * a[r1][c0]) / det);
      }
  }
};
const YuvFromRgb k_yuv;

}  // namespace

void bonn_undecorrelate(const Config& cfg, const float* in, float* rgb) {
  // YCoCg -> RGB (BTFLIB undecorrelate.m, model 4).
  static constexpr float k_rgb_from_ycocg[3][3] = {{1, 1, -1}, {1, 0, 1}, {1, -1, -1}};
  auto mul = [&](const float (*M)[3], const float* v) {
    for (int c = 0; c < 3; ++c) rgb[c] = M[c][0] * v[0] + M[c][1] * v[1] + M[c][2] * v[2];
  };
  switch (cfg.color_model) {
    case 0:
      for (int c = 0; c < 3; ++c) rgb[c] = in[c];
      return;
    case 1:
      return mul(k_rgb_from_yuv, in);
    case 3:  // PCA: row vector times T, plus the mean
      for (int j = 0; j < 3; ++j)
        rgb[j] = in[0] * cfg.color_transform[0][j] + in[1] * cfg.color_transform[1][j] + in[2] * cfg.color_transform[2][j] +
                 cfg.color_mean[j];
      return;
    case 4:
      return mul(k_rgb_from_ycocg, in);
    case 9: {
      const float yuv[3] = {std::exp(in[0]) - k_drr_eps, in[1], in[2]};
      return mul(k_rgb_from_yuv, yuv);
    }
    case 10: {
      // sign(v) * exp(|v| + log eps); sign(0) = 0 as in MATLAB.
      auto unlog = [](float v) { return v == 0 ? 0.0f : std::copysign(k_drr_eps * std::exp(std::fabs(v)), v); };
      const float yuv[3] = {std::exp(in[0]) - k_drr_eps, unlog(in[1]), unlog(in[2])};
      return mul(k_rgb_from_yuv, yuv);
    }
    case 12:
      for (int c = 0; c < 3; ++c) rgb[c] = std::exp(in[c]) - k_drr_eps;
      return;
    default:  // 11 never reaches here (native); make_fmf_model rejects the rest
      for (int c = 0; c < 3; ++c) rgb[c] = 0;
  }
}

}  // namespace fmf

using namespace fmf;

Result<std::unique_ptr<Model>> make_fmf_model(const BtfDesc& desc, int cm, std::vector<FmfFactors> in,
                                              const float color_mean[3], const float color_transform[3][3], bool half,
                                              float dfmf_offset) {
  BTFC_RETURN_IF_ERROR(desc.validate());
  if (!(std::isfinite(dfmf_offset) && dfmf_offset > 0))
    return invalid_argument("fmf: dfmf luminance offset " + std::to_string(dfmf_offset) + " is not a positive number");
  const bool per_channel = in.size() == 3;
  if (in.size() != 1 && !per_channel)
    return invalid_argument("fmf: a Bonn factorization needs 1 (rgb) or 3 (per channel) blocks, got " + std::to_string(in.size()));
  if (per_channel && desc.channels != 3)
    return unsupported("fmf: per-channel (DFMF) factorizations are supported for 3 channels only, this one has " +
                       std::to_string(desc.channels));
  const bool ok_model = per_channel ? (cm == 0 || cm == 1 || cm == 3 || cm == 4 || (cm >= 9 && cm <= 12)) : (cm == 0 || cm == 12);
  if (!ok_model)
    return unsupported("fmf: Bonn colour model " + std::to_string(cm) +
                       (cm == 2 ? " (Lab)" : cm == 5 || cm == 6 ? " (spectral)" : "") + " is not supported" +
                       (per_channel ? "" : " for an FMF (one rgb block)"));
  Config cfg;
  cfg.dfmf = per_channel;
  cfg.half = half;
  cfg.color_model = (per_channel && cm == 11) || (!per_channel && cm == 0) ? -1 : cm;
  for (int i = 0; i < 3; ++i) {
    cfg.color_mean[i] = color_mean ? color_mean[i] : 0.0f;
    for (int j = 0; j < 3; ++j) cfg.color_transform[i][j] = color_transform ? color_transform[i][j] : float(i == j);
  }
  const size_t rows = per_channel ? desc.num_images() : desc.abrdf_size(), texels = desc.num_texels();
  std::vector<Block> blocks;
  for (FmfFactors& f : in) {
    const std::string what = "fmf: block '" + f.name + "'";
    if (f.C < 1 || f.C > 4096) return unsupported(what + " has " + std::to_string(f.C) + " components (1..4096 supported)");
    const size_t C = size_t(f.C);
    if (f.U.size() != rows * C || f.SxV.size() != texels * C || f.S.size() != C)
      return invalid_argument(what + ": U, SxV or S size disagrees with " + std::to_string(rows) + " rows, " +
                              std::to_string(texels) + " texels, " + std::to_string(C) + " components");
    Block b;
    b.name = f.name;
    b.U = Eigen::Map<const MatrixXfR>(f.U.data(), Index(rows), Index(C));
    std::vector<float>().swap(f.U);  // release as we go: peak memory = model + one block
    b.SxV = Eigen::Map<const MatrixXfR>(f.SxV.data(), Index(texels), Index(C));
    std::vector<float>().swap(f.SxV);
    b.S = Eigen::Map<const Eigen::VectorXf>(f.S.data(), Index(C));
    // The factors are stored exactly (no per-component scale): a half Bonn file saves to a
    // half .btfc without a second rounding.
    b.scale = Eigen::VectorXf::Ones(Index(C));
    if (!b.U.allFinite() || !b.SxV.allFinite()) return corrupt_data(what + " holds non-finite values");
    blocks.push_back(std::move(b));
  }
  char eps[32];  // the luminance offset (colour model 11's, or a btfc model's own), not "automatic"
  const float e = per_channel && cm == 11 ? dfmf_offset : k_drr_eps;
  if (e == k_drr_eps) std::snprintf(eps, sizeof eps, "%s", std::to_string(k_drr_eps).c_str());  // as before: "0.000010"
  else std::snprintf(eps, sizeof eps, "%.9g", double(e));
  std::string text = per_channel ? "rank=" + std::to_string(blocks[0].U.cols()) + ":chroma_rank=" +
                                       std::to_string(std::max(blocks[1].U.cols(), blocks[2].U.cols())) + ":color=dfmf:offset=" + eps
                                 : "rank=" + std::to_string(blocks[0].U.cols()) + ":color=rgb";
  text += half ? ":precision=half" : ":precision=float";
  BTFC_ASSIGN_OR_RETURN(auto spec, parse_spec_string("fmf:" + text));
  BTFC_ASSIGN_OR_RETURN(Params p, bind_params(spec, params_table()));
  cfg.offset = config_from(p).offset;
  auto model = std::make_unique<FmfModel>(desc, p.canonical(), cfg, std::move(blocks));
  for (const Block& b : model->blocks()) model->mutable_stats().add("rank." + b.name, double(b.U.cols()));
  model->mutable_stats().add("bonn_color_model", cm);
  return std::unique_ptr<Model>(std::move(model));
}

namespace {

// log(x) for normal finite x > 0 in plain arithmetic the compiler vectorizes (std::log is a call
// per value: the conversion of a UBO2003-size BTF took 0.13 s per 3328-texel chunk with it,
// 0.017 s vectorized, measured in a scratch harness). Cephes' logf: x = 2^e m, m in
// [sqrt(1/2), sqrt(2)), a degree-9 polynomial in m - 1; within 2e-7 relative of std::log on
// the data measured. Callers send other x (zero, denormal, inf, NaN) to std::log.
// The polynomial's coefficients, shared by the scalar function and the AVX2 kernel's lanes.
constexpr float k_log_a[4] = {3.3333331174e-1f, 2.0000714765e-1f, 1.4249322787e-1f, 1.1676998740e-1f};
constexpr float k_log_b[4] = {2.4999993993e-1f, 1.6668057665e-1f, 1.2420140846e-1f, 1.1514610310e-1f};
constexpr float k_log_top = 7.0376836292e-2f, k_log_e_lo = -2.12194440e-4f, k_log_e_hi = 0.693359375f;
constexpr float k_sqrt_half = 0.70710678f;
inline float log_normal(float x) {
  uint32_t i;
  std::memcpy(&i, &x, 4);
  int e = int((i >> 23) & 0xff) - 126;
  const uint32_t mi = (i & 0x7fffffu) | 0x3f000000u;  // [0.5, 1)
  float m;
  std::memcpy(&m, &mi, 4);
  // m < sqrt(1/2), compared as the bit patterns of positive floats (the same order): a float
  // compare here kept GCC from vectorizing the loop without AVX-512 (trapping math).
  const bool low = mi < std::bit_cast<uint32_t>(k_sqrt_half);
  e -= int(low);
  m = m * (low ? 2.0f : 1.0f) - 1.0f;  // m + m or m, exactly; a conditional add is a branch too
  const float z = m * m;
  // Estrin's scheme (depth 4 multiply-adds where Horner's chain is 9: the chain's latency bounded
  // the conversion loop, 0.46 s per pass over a UBO2003-size BTF on 2 Zen 3 cores).
  const float z2 = z * z;
  const float q0 = k_log_a[0] - k_log_b[0] * m, q1 = k_log_a[1] - k_log_b[1] * m;
  const float q2 = k_log_a[2] - k_log_b[2] * m, q3 = k_log_a[3] - k_log_b[3] * m;
  const float r0 = q0 + q1 * z, r1 = q2 + q3 * z;
  float y = (r0 + r1 * z2) + k_log_top * (z2 * z2);
  y = y * m * z;
  const float fe = float(e);
  y += k_log_e_lo * fe;
  y += -0.5f * z;
  return (m + y) + k_log_e_hi * fe;
}

// (a0 R + a1 G) + a2 B of one triple.
inline float dot3_scalar(const float* a, const float* p) { return a[0] * p[0] + a[1] * p[1] + a[2] * p[2]; }

// The three channels of `rows` RGB triples; the body of the builds below. The arithmetic is the
// same IEEE operations in the same order in all (no FMA: this file is compiled with
// -ffp-contract=off, CMakeLists.txt), so the AVX-512 and AVX2 builds return the generic build's bits.
__attribute__((always_inline)) inline size_t channels_body(const float* abrdf, size_t rows, float offset, float* y, float* u,
                                                          float* v) {
  size_t clamped = 0;
  int odd = 0;
  const float a0 = k_yuv.m[0][0], a1 = k_yuv.m[0][1], a2 = k_yuv.m[0][2], b0 = k_yuv.m[1][0], b1 = k_yuv.m[1][1],
              b2 = k_yuv.m[1][2], c0 = k_yuv.m[2][0], c1 = k_yuv.m[2][1], c2 = k_yuv.m[2][2];
  // The count in 32-bit lanes, as wide as the floats' (a 64-bit count kept GCC from vectorizing
  // the loop for AVX2), per block of at most 2^30 rows.
  for (size_t r0 = 0; r0 < rows; r0 += size_t(1) << 30) {
  const size_t r1 = std::min(rows, r0 + (size_t(1) << 30));
  uint32_t count = 0;
#pragma omp simd reduction(+ : count) reduction(| : odd)
  for (size_t r = r0; r < r1; ++r) {
    const float R = abrdf[3 * r], G = abrdf[3 * r + 1], B = abrdf[3 * r + 2];
    float l = a0 * R + a1 * G + a2 * B;
    count += uint32_t(l < 0);
    l = std::max(l, 0.0f);
    const float d = l + offset;
    u[r] = (b0 * R + b1 * G + b2 * B) / d;
    v[r] = (c0 * R + c1 * G + c2 * B) / d;
    y[r] = log_normal(d);
    odd |= int(!(d >= 1.17549435e-38f) | !(d <= 3.40282347e38f));
  }
  clamped += count;
  }
  if (odd)  // zero, denormal, inf or NaN sums: std::log's answer (NaN stays NaN)
    for (size_t r = 0; r < rows; ++r) {
      const float d = std::max(dot3_scalar(k_yuv.m[0], abrdf + 3 * r), 0.0f) + offset;  // as above: NaN stays
      if (!(d >= 1.17549435e-38f && d <= 3.40282347e38f)) y[r] = std::log(d);
    }
  return clamped;
}

size_t channels_generic(const float* abrdf, size_t rows, float offset, float* y, float* u, float* v) {
  return channels_body(abrdf, rows, offset, y, u, v);
}
#if defined(__x86_64__) && defined(__GNUC__)
// AVX2 by hand: GCC's vectorization of channels_body for AVX2 took 2.1 ns per row and core with
// the data in cache, this kernel 1.8 ns (2.9 and 2.7 ns from memory; scratch harness on Zen 3).
// No FMA and every operation in channels_body's order, so the same bits as the generic build
// (tests/ooc_dfmf_test.cpp compares them).

// How far ahead (rows of 12 bytes) the channels kernels prefetch their input: GCC's loops ran at
// 0.78 ns per row and core with the input in cache (AVX-512) but at 1.9 ns from memory on a
// 2-core Xeon reading 28 GB/s, the loop's body too long for the core to run far enough ahead on
// its own. Scratch harness, parts as the encode's: 64 rows ahead 1.45-1.6 ns, 128 1.3-1.5,
// 192-1024 1.4-1.6 (AVX2 build: 2.3-2.5 without).
constexpr size_t k_channels_ahead = 128;
// Asks for the cache lines of rows [r + k_channels_ahead, + n) while rows r.. compute, when they
// lie within the `rows` of this call.
__attribute__((always_inline)) inline void prefetch_ahead(const float* abrdf, size_t r, size_t n, size_t rows) {
  if (r + k_channels_ahead + n > rows) return;
  const uintptr_t first = reinterpret_cast<uintptr_t>(abrdf + 3 * (r + k_channels_ahead));
  for (uintptr_t a = first & ~uintptr_t(63); a < first + 12 * n; a += 64) _mm_prefetch(reinterpret_cast<const char*>(a), _MM_HINT_T0);
}

// Rows r..r+7 of an RGB-triple array (24 floats from p) as R, G, B lanes: R sits in lanes
// {0,3,6} of the first load, {1,4,7} of the second and {2,5} of the third, so two blends gather
// them into one register and a permute puts them in order; G and B likewise, rotated.
__attribute__((target("avx2"), always_inline)) inline void rgb8(const float* p, __m256& R, __m256& G, __m256& B) {
  const __m256 v0 = _mm256_loadu_ps(p), v1 = _mm256_loadu_ps(p + 8), v2 = _mm256_loadu_ps(p + 16);
  R = _mm256_permutevar8x32_ps(_mm256_blend_ps(_mm256_blend_ps(v0, v1, 0x92), v2, 0x24), _mm256_setr_epi32(0, 3, 6, 1, 4, 7, 2, 5));
  G = _mm256_permutevar8x32_ps(_mm256_blend_ps(_mm256_blend_ps(v0, v1, 0x24), v2, 0x49), _mm256_setr_epi32(1, 4, 7, 2, 5, 0, 3, 6));
  B = _mm256_permutevar8x32_ps(_mm256_blend_ps(_mm256_blend_ps(v0, v1, 0x49), v2, 0x92), _mm256_setr_epi32(2, 5, 0, 3, 6, 1, 4, 7));
}
// (a0 R + a1 G) + a2 B, as the scalar expression rounds it.
__attribute__((target("avx2"), always_inline)) inline __m256 dot3(const float* a, __m256 R, __m256 G, __m256 B) {
  return _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(_mm256_set1_ps(a[0]), R), _mm256_mul_ps(_mm256_set1_ps(a[1]), G)),
                       _mm256_mul_ps(_mm256_set1_ps(a[2]), B));
}
// log_normal on 8 lanes, its operations in its order.
__attribute__((target("avx2"), always_inline)) inline __m256 log_normal8(__m256 x) {
  const __m256i i = _mm256_castps_si256(x);
  __m256i e = _mm256_sub_epi32(_mm256_and_si256(_mm256_srli_epi32(i, 23), _mm256_set1_epi32(0xff)), _mm256_set1_epi32(126));
  const __m256i mi = _mm256_or_si256(_mm256_and_si256(i, _mm256_set1_epi32(0x7fffff)), _mm256_set1_epi32(0x3f000000));
  // Both positive below 2^31: the signed compare is the unsigned one. low is -1 where true.
  const __m256i low = _mm256_cmpgt_epi32(_mm256_set1_epi32(int(std::bit_cast<uint32_t>(k_sqrt_half))), mi);
  e = _mm256_add_epi32(e, low);
  const __m256 one = _mm256_set1_ps(1.0f);
  const __m256 m = _mm256_sub_ps(_mm256_mul_ps(_mm256_castsi256_ps(mi), _mm256_blendv_ps(one, _mm256_set1_ps(2.0f), _mm256_castsi256_ps(low))), one);
  const __m256 z = _mm256_mul_ps(m, m), z2 = _mm256_mul_ps(z, z);
  __m256 q[4];
  for (int k = 0; k < 4; ++k) q[k] = _mm256_sub_ps(_mm256_set1_ps(k_log_a[k]), _mm256_mul_ps(_mm256_set1_ps(k_log_b[k]), m));
  const __m256 r0 = _mm256_add_ps(q[0], _mm256_mul_ps(q[1], z)), r1 = _mm256_add_ps(q[2], _mm256_mul_ps(q[3], z));
  __m256 y = _mm256_add_ps(_mm256_add_ps(r0, _mm256_mul_ps(r1, z2)), _mm256_mul_ps(_mm256_set1_ps(k_log_top), _mm256_mul_ps(z2, z2)));
  y = _mm256_mul_ps(_mm256_mul_ps(y, m), z);
  const __m256 fe = _mm256_cvtepi32_ps(e);
  y = _mm256_add_ps(y, _mm256_mul_ps(_mm256_set1_ps(k_log_e_lo), fe));
  y = _mm256_add_ps(y, _mm256_mul_ps(_mm256_set1_ps(-0.5f), z));
  return _mm256_add_ps(_mm256_add_ps(m, y), _mm256_mul_ps(_mm256_set1_ps(k_log_e_hi), fe));
}
__attribute__((target("avx2"))) size_t channels_avx2(const float* abrdf, size_t rows, float offset, float* y, float* u, float* v) {
  const __m256 off = _mm256_set1_ps(offset), zero = _mm256_setzero_ps();
  const __m256 lo = _mm256_set1_ps(1.17549435e-38f), hi = _mm256_set1_ps(3.40282347e38f);
  size_t clamped = 0, r = 0;
  __m256 odd = zero;
  while (r + 8 <= rows) {
    __m256i count = _mm256_setzero_si256();  // per lane, flushed every 2^28 groups
    for (size_t g = 0; g < (size_t(1) << 28) && r + 8 <= rows; ++g, r += 8) {
      prefetch_ahead(abrdf, r, 8, rows);
      __m256 R, G, B;
      rgb8(abrdf + 3 * r, R, G, B);
      const __m256 l = dot3(k_yuv.m[0], R, G, B);
      count = _mm256_sub_epi32(count, _mm256_castps_si256(_mm256_cmp_ps(l, zero, _CMP_LT_OQ)));
      const __m256 d = _mm256_add_ps(_mm256_max_ps(zero, l), off);  // max(0, NaN) is NaN, as std::max(l, 0.0f)
      _mm256_storeu_ps(u + r, _mm256_div_ps(dot3(k_yuv.m[1], R, G, B), d));
      _mm256_storeu_ps(v + r, _mm256_div_ps(dot3(k_yuv.m[2], R, G, B), d));
      _mm256_storeu_ps(y + r, log_normal8(d));
      odd = _mm256_or_ps(odd, _mm256_or_ps(_mm256_cmp_ps(d, lo, _CMP_NGE_UQ), _mm256_cmp_ps(d, hi, _CMP_NLE_UQ)));
    }
    alignas(32) uint32_t c[8];
    _mm256_store_si256(reinterpret_cast<__m256i*>(c), count);
    for (uint32_t n : c) clamped += n;
  }
  if (!_mm256_testz_ps(odd, odd))  // as channels_body: std::log's answer for sums that are not normal
    for (size_t k = 0; k < r; ++k) {
      const float d = std::max(dot3_scalar(k_yuv.m[0], abrdf + 3 * k), 0.0f) + offset;
      if (!(d >= 1.17549435e-38f && d <= 3.40282347e38f)) y[k] = std::log(d);
    }
  return clamped + channels_body(abrdf + 3 * r, rows - r, offset, y + r, u + r, v + r);
}
// Channel c of rows r..r+15 (48 floats from p, loaded as v0..v2): lane i is float 3 i + c,
// found in (v0, v1) by one two-source permute when below 32, then the rest from v2 by a second.
struct RgbIndex16 {
  alignas(64) int first[3][16], second[3][16];
  constexpr RgbIndex16() : first{}, second{} {
    for (int c = 0; c < 3; ++c)
      for (int i = 0; i < 16; ++i) {
        const int p = 3 * i + c;
        first[c][i] = p < 32 ? p : 0;
        second[c][i] = p < 32 ? i : 16 + (p - 32);
      }
  }
};
constexpr RgbIndex16 k_rgb16;
__attribute__((target("avx512f"), always_inline)) inline __m512 channel16(int c, __m512 v0, __m512 v1, __m512 v2) {
  const __m512 t = _mm512_permutex2var_ps(v0, _mm512_load_si512(k_rgb16.first[c]), v1);
  return _mm512_permutex2var_ps(t, _mm512_load_si512(k_rgb16.second[c]), v2);
}
// (a0 R + a1 G) + a2 B on 16 lanes, as the scalar expression rounds it.
__attribute__((target("avx512f"), always_inline)) inline __m512 dot3_16(const float* a, __m512 R, __m512 G, __m512 B) {
  return _mm512_add_ps(_mm512_add_ps(_mm512_mul_ps(_mm512_set1_ps(a[0]), R), _mm512_mul_ps(_mm512_set1_ps(a[1]), G)),
                       _mm512_mul_ps(_mm512_set1_ps(a[2]), B));
}
// log_normal on 16 lanes, its operations in its order.
__attribute__((target("avx512f"), always_inline)) inline __m512 log_normal16(__m512 x) {
  const __m512i i = _mm512_castps_si512(x);
  __m512i e = _mm512_sub_epi32(_mm512_and_si512(_mm512_maskz_srli_epi32(0xffff, i, 23), _mm512_set1_epi32(0xff)), _mm512_set1_epi32(126));
  const __m512i mi = _mm512_or_si512(_mm512_and_si512(i, _mm512_set1_epi32(0x7fffff)), _mm512_set1_epi32(0x3f000000));
  const __mmask16 low = _mm512_cmplt_epi32_mask(mi, _mm512_set1_epi32(int(std::bit_cast<uint32_t>(k_sqrt_half))));
  e = _mm512_mask_sub_epi32(e, low, e, _mm512_set1_epi32(1));
  const __m512 one = _mm512_set1_ps(1.0f);
  const __m512 m = _mm512_sub_ps(_mm512_mul_ps(_mm512_castsi512_ps(mi), _mm512_mask_blend_ps(low, one, _mm512_set1_ps(2.0f))), one);
  const __m512 z = _mm512_mul_ps(m, m), z2 = _mm512_mul_ps(z, z);
  __m512 q[4];
  for (int k = 0; k < 4; ++k) q[k] = _mm512_sub_ps(_mm512_set1_ps(k_log_a[k]), _mm512_mul_ps(_mm512_set1_ps(k_log_b[k]), m));
  const __m512 r0 = _mm512_add_ps(q[0], _mm512_mul_ps(q[1], z)), r1 = _mm512_add_ps(q[2], _mm512_mul_ps(q[3], z));
  __m512 y = _mm512_add_ps(_mm512_add_ps(r0, _mm512_mul_ps(r1, z2)), _mm512_mul_ps(_mm512_set1_ps(k_log_top), _mm512_mul_ps(z2, z2)));
  y = _mm512_mul_ps(_mm512_mul_ps(y, m), z);
  const __m512 fe = _mm512_maskz_cvtepi32_ps(0xffff, e);  // maskz: see moments_avx512
  y = _mm512_add_ps(y, _mm512_mul_ps(_mm512_set1_ps(k_log_e_lo), fe));
  y = _mm512_add_ps(y, _mm512_mul_ps(_mm512_set1_ps(-0.5f), z));
  return _mm512_add_ps(_mm512_add_ps(m, y), _mm512_mul_ps(_mm512_set1_ps(k_log_e_hi), fe));
}
// By hand as channels_avx2, so that it can prefetch (prefetch_ahead); the same bits as
// channels_body (tests/ooc_dfmf_test.cpp compares them).
__attribute__((target("avx512f"))) size_t channels_avx512(const float* abrdf, size_t rows, float offset, float* y, float* u, float* v) {
  const __m512 off = _mm512_set1_ps(offset), zero = _mm512_setzero_ps();
  const __m512 lo = _mm512_set1_ps(1.17549435e-38f), hi = _mm512_set1_ps(3.40282347e38f);
  __m512i count = _mm512_setzero_si512();  // per lane: at most rows / 16 < 2^32 each
  __mmask16 odd = 0;
  size_t r = 0;
  for (; r + 16 <= rows; r += 16) {
    const float* p = abrdf + 3 * r;
    prefetch_ahead(abrdf, r, 16, rows);
    const __m512 v0 = _mm512_loadu_ps(p), v1 = _mm512_loadu_ps(p + 16), v2 = _mm512_loadu_ps(p + 32);
    const __m512 R = channel16(0, v0, v1, v2), G = channel16(1, v0, v1, v2), B = channel16(2, v0, v1, v2);
    const __m512 l = dot3_16(k_yuv.m[0], R, G, B);
    count = _mm512_mask_add_epi32(count, _mm512_cmp_ps_mask(l, zero, _CMP_LT_OQ), count, _mm512_set1_epi32(1));
    // max(0, NaN) is NaN, as std::max(l, 0.0f); the maskz form: see moments_avx512
    const __m512 d = _mm512_add_ps(_mm512_maskz_max_ps(0xffff, zero, l), off);
    _mm512_storeu_ps(u + r, _mm512_div_ps(dot3_16(k_yuv.m[1], R, G, B), d));
    _mm512_storeu_ps(v + r, _mm512_div_ps(dot3_16(k_yuv.m[2], R, G, B), d));
    _mm512_storeu_ps(y + r, log_normal16(d));
    odd |= _mm512_cmp_ps_mask(d, lo, _CMP_NGE_UQ) | _mm512_cmp_ps_mask(d, hi, _CMP_NLE_UQ);
  }
  alignas(64) uint32_t c[16];
  _mm512_store_si512(c, count);
  size_t clamped = 0;
  for (uint32_t n : c) clamped += n;
  if (odd)  // as channels_body: std::log's answer for sums that are not normal
    for (size_t k = 0; k < r; ++k) {
      const float d = std::max(dot3_scalar(k_yuv.m[0], abrdf + 3 * k), 0.0f) + offset;
      if (!(d >= 1.17549435e-38f && d <= 3.40282347e38f)) y[k] = std::log(d);
    }
  return clamped + channels_body(abrdf + 3 * r, rows - r, offset, y + r, u + r, v + r);
}
#endif

}  // namespace

size_t dfmf_channels(const float* abrdf, size_t rows, float offset, float* y, float* u, float* v) {
#if defined(__x86_64__) && defined(__GNUC__)
  static const bool avx512 = cpu_has_avx512f(), avx2 = cpu_has_avx2_fma();
  if (avx512) return channels_avx512(abrdf, rows, offset, y, u, v);
  if (avx2) return channels_avx2(abrdf, rows, offset, y, u, v);
#endif
  return channels_generic(abrdf, rows, offset, y, u, v);
}

size_t dfmf_channels_reference(const float* abrdf, size_t rows, float offset, float* y, float* u, float* v) {
  return channels_generic(abrdf, rows, offset, y, u, v);
}

bool dfmf_channels_avx2(const float* abrdf, size_t rows, float offset, float* y, float* u, float* v, size_t* clamped) {
#if defined(__x86_64__) && defined(__GNUC__)
  if (!cpu_has_avx2_fma()) return false;
  *clamped = channels_avx2(abrdf, rows, offset, y, u, v);
  return true;
#else
  (void)abrdf, (void)rows, (void)offset, (void)y, (void)u, (void)v, (void)clamped;
  return false;
#endif
}

size_t dfmf_channel(const float* abrdf, size_t rows, int k, float offset, float* out) {
  // dfmf_channels in blocks, keeping channel k: the same bits as the fused path.
  constexpr size_t k_block = 512;
  float buf[2][k_block];
  size_t clamped = 0;
  for (size_t r = 0; r < rows; r += k_block) {
    const size_t h = std::min(k_block, rows - r);
    float* ch[3];
    for (int i = 0, b = 0; i < 3; ++i) ch[i] = i == k ? out + r : buf[b++];  // channel k straight into out
    clamped += dfmf_channels(abrdf + 3 * r, h, offset, ch[0], ch[1], ch[2]);
  }
  return clamped;
}

namespace {

// The sums of one texel, vectorized: lanes sum in their own order, so the AVX-512, AVX2 and generic
// builds may differ in the last bits of a sum (the offset is printed to 9 digits; the processes of
// one factorization use the allreduced total, the same on all). Also whether a luminance was not
// finite: a NaN or inf value makes its Y NaN or inf (0 x inf is NaN too).
__attribute__((always_inline)) inline bool moments_body(const float* abrdf, size_t rows, double* sum_y, double* sum_y2) {
  const float a0 = k_yuv.m[0][0], a1 = k_yuv.m[0][1], a2 = k_yuv.m[0][2];
  double s = 0, s2 = 0;
  int bad = 0;
#pragma omp simd reduction(+ : s, s2) reduction(| : bad)
  for (size_t r = 0; r < rows; ++r) {
    const float l = a0 * abrdf[3 * r] + a1 * abrdf[3 * r + 1] + a2 * abrdf[3 * r + 2];
    bad |= int(!(l >= -3.40282347e38f) | !(l <= 3.40282347e38f));
    const double y = std::max(0.0f, l);
    s += y, s2 += y * y;
  }
  *sum_y += s, *sum_y2 += s2;
  return bad != 0;
}
bool moments_generic(const float* abrdf, size_t rows, double* sum_y, double* sum_y2) { return moments_body(abrdf, rows, sum_y, sum_y2); }
#if defined(__x86_64__) && defined(__GNUC__)
// By hand as the AVX2 kernel below: GCC left moments_body scalar for AVX-512 too (the float lanes
// and the double sums have different widths), which made the moments pass of a color=dfmf encode
// cost about as much as the three conversions together on a 2-core Xeon (perf, bench_fmf rank 16).
__attribute__((target("avx512f"))) bool moments_avx512(const float* abrdf, size_t rows, double* sum_y, double* sum_y2) {
  const __m512 zero = _mm512_setzero_ps(), big = _mm512_set1_ps(3.40282347e38f), nbig = _mm512_set1_ps(-3.40282347e38f);
  const __m512 a0 = _mm512_set1_ps(k_yuv.m[0][0]), a1 = _mm512_set1_ps(k_yuv.m[0][1]), a2 = _mm512_set1_ps(k_yuv.m[0][2]);
  __m512d s[2] = {_mm512_setzero_pd(), _mm512_setzero_pd()}, s2[2] = {_mm512_setzero_pd(), _mm512_setzero_pd()};
  __mmask16 bad = 0;
  size_t r = 0;
  for (; r + 16 <= rows; r += 16) {
    const float* p = abrdf + 3 * r;
    prefetch_ahead(abrdf, r, 16, rows);
    const __m512 v0 = _mm512_loadu_ps(p), v1 = _mm512_loadu_ps(p + 16), v2 = _mm512_loadu_ps(p + 32);
    const __m512 R = channel16(0, v0, v1, v2), G = channel16(1, v0, v1, v2), B = channel16(2, v0, v1, v2);
    const __m512 l = _mm512_add_ps(_mm512_add_ps(_mm512_mul_ps(a0, R), _mm512_mul_ps(a1, G)), _mm512_mul_ps(a2, B));
    bad |= _mm512_cmp_ps_mask(l, nbig, _CMP_NGE_UQ) | _mm512_cmp_ps_mask(l, big, _CMP_NLE_UQ);
    // The maskz forms with full masks are the same instructions; GCC 12's unmasked ones pass an
    // "undefined" register it then warns about (its bug 105593).
    const __m512 y = _mm512_maskz_max_ps(0xffff, l, zero);  // NaN -> 0, as std::max(0.0f, l)
    const __m512d y0 = _mm512_maskz_cvtps_pd(0xff, _mm256_castpd_ps(_mm512_maskz_extractf64x4_pd(0xf, _mm512_castps_pd(y), 0)));
    const __m512d y1 = _mm512_maskz_cvtps_pd(0xff, _mm256_castpd_ps(_mm512_maskz_extractf64x4_pd(0xf, _mm512_castps_pd(y), 1)));
    s[0] = _mm512_add_pd(s[0], y0), s[1] = _mm512_add_pd(s[1], y1);
    s2[0] = _mm512_add_pd(s2[0], _mm512_mul_pd(y0, y0)), s2[1] = _mm512_add_pd(s2[1], _mm512_mul_pd(y1, y1));
  }
  alignas(64) double a[8], b[8];  // not _mm512_reduce_add_pd: it warns as above
  _mm512_store_pd(a, _mm512_add_pd(s[0], s[1]));
  _mm512_store_pd(b, _mm512_add_pd(s2[0], s2[1]));
  *sum_y += ((a[0] + a[1]) + (a[2] + a[3])) + ((a[4] + a[5]) + (a[6] + a[7]));
  *sum_y2 += ((b[0] + b[1]) + (b[2] + b[3])) + ((b[4] + b[5]) + (b[6] + b[7]));
  const bool tail_bad = moments_body(abrdf + 3 * r, rows - r, sum_y, sum_y2);
  return tail_bad || bad != 0;
}
// By hand: GCC leaves moments_body scalar for AVX2 (the float lanes and the double sums have
// different widths), 7.8 GB/s on 2 Zen 3 cores; this kernel 15 GB/s (scratch harness).
__attribute__((target("avx2"))) bool moments_avx2(const float* abrdf, size_t rows, double* sum_y, double* sum_y2) {
  const __m256 zero = _mm256_setzero_ps(), big = _mm256_set1_ps(3.40282347e38f), nbig = _mm256_set1_ps(-3.40282347e38f);
  __m256d s[2] = {_mm256_setzero_pd(), _mm256_setzero_pd()}, s2[2] = {_mm256_setzero_pd(), _mm256_setzero_pd()};
  __m256 bad = zero;
  size_t r = 0;
  for (; r + 8 <= rows; r += 8) {
    prefetch_ahead(abrdf, r, 8, rows);
    __m256 R, G, B;
    rgb8(abrdf + 3 * r, R, G, B);
    const __m256 l = dot3(k_yuv.m[0], R, G, B);
    bad = _mm256_or_ps(bad, _mm256_or_ps(_mm256_cmp_ps(l, nbig, _CMP_NGE_UQ), _mm256_cmp_ps(l, big, _CMP_NLE_UQ)));
    const __m256 y = _mm256_max_ps(l, zero);  // NaN -> 0, as std::max(0.0f, l)
    const __m256d y0 = _mm256_cvtps_pd(_mm256_castps256_ps128(y)), y1 = _mm256_cvtps_pd(_mm256_extractf128_ps(y, 1));
    s[0] = _mm256_add_pd(s[0], y0), s[1] = _mm256_add_pd(s[1], y1);
    s2[0] = _mm256_add_pd(s2[0], _mm256_mul_pd(y0, y0)), s2[1] = _mm256_add_pd(s2[1], _mm256_mul_pd(y1, y1));
  }
  alignas(32) double a[4], b[4];
  _mm256_store_pd(a, _mm256_add_pd(s[0], s[1]));
  _mm256_store_pd(b, _mm256_add_pd(s2[0], s2[1]));
  *sum_y += (a[0] + a[1]) + (a[2] + a[3]);
  *sum_y2 += (b[0] + b[1]) + (b[2] + b[3]);
  const bool tail_bad = moments_body(abrdf + 3 * r, rows - r, sum_y, sum_y2);
  return tail_bad || !_mm256_testz_ps(bad, bad);
}
#endif

}  // namespace

bool dfmf_luminance_moments(const float* abrdf, size_t rows, double* sum_y, double* sum_y2) {
#if defined(__x86_64__) && defined(__GNUC__)
  static const bool avx512 = cpu_has_avx512f(), avx2 = cpu_has_avx2_fma();
  if (avx512) return moments_avx512(abrdf, rows, sum_y, sum_y2);
  if (avx2) return moments_avx2(abrdf, rows, sum_y, sum_y2);
#endif
  return moments_generic(abrdf, rows, sum_y, sum_y2);
}

bool dfmf_luminance_moments_reference(const float* abrdf, size_t rows, double* sum_y, double* sum_y2) {
  return moments_generic(abrdf, rows, sum_y, sum_y2);
}

bool dfmf_luminance_moments_avx2(const float* abrdf, size_t rows, double* sum_y, double* sum_y2, bool* bad) {
#if defined(__x86_64__) && defined(__GNUC__)
  if (!cpu_has_avx2_fma()) return false;
  *bad = moments_avx2(abrdf, rows, sum_y, sum_y2);
  return true;
#else
  (void)abrdf, (void)rows, (void)sum_y, (void)sum_y2, (void)bad;
  return false;
#endif
}

double dfmf_auto_offset(double sum_y, double sum_y2) {
  // No floor at Bonn's 1e-5: on data scaled below it (HDR stored in physical units, 1e-6-size
  // values) a fixed 1e-5 dwarfs every luminance, Y' = log(Y + e) then barely moves, and its half
  // floats' steps became 13-27 % errors (a 4 x 4 synth times 1e-6: relative L2 0.27 against 9e-4
  // at scale 1). The smallest normal float keeps e a normal float for data near underflow.
  // e is at most the largest luminance, a float; the ceiling keeps its 9-digit spelling in the
  // spec (dfmf_with_offset) within the parameter's range.
  const double e = sum_y > 0 ? sum_y2 / sum_y : 0;
  return std::isfinite(e) && e > 0 ? std::clamp(e, double(std::numeric_limits<float>::min()), k_dfmf_max_offset) : k_drr_eps;
}

std::vector<size_t> dfmf_offset_sample(size_t texels) {
  const size_t m = std::min<size_t>(texels, 4096);
  std::vector<size_t> t(m);
  for (size_t i = 0; i < m; ++i) t[i] = size_t((unsigned __int128)i * texels / m);  // no overflow at any size
  return t;
}

double dfmf_offset_from_sample(const std::vector<double>& sums) {
  double sy = 0, sy2 = 0;
  for (size_t i = 0; i + 1 < sums.size(); i += 2) sy += sums[i], sy2 += sums[i + 1];
  return dfmf_auto_offset(sy, sy2);
}

double dfmf_auto_offset(const Btf& btf) {
  const std::vector<size_t> sample = dfmf_offset_sample(btf.desc().num_texels());
  std::vector<double> sums(2 * sample.size(), 0.0);
  const size_t rows = btf.desc().num_images();
  // Each texel's sums from zero into its own slots: the same bits on any thread count.
#pragma omp parallel for schedule(static)
  for (long long i = 0; i < (long long)sample.size(); ++i)
    dfmf_luminance_moments(btf.abrdf(sample[size_t(i)]), rows, &sums[2 * size_t(i)], &sums[2 * size_t(i) + 1]);
  return dfmf_offset_from_sample(sums);
}

Result<Params> dfmf_with_offset(const Params& p, double offset) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.9g", offset);
  return with_value(p, "offset", buf, params_table());
}

}  // namespace btfc
