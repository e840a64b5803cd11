// Error metrics (core/metrics.h). Two passes over the data:
//  1. one streaming pass over the texel-major buffer for the error sums and the reference
//     maximum (contiguous reads, OpenMP reduction over texels);
//  2. with SSIM, the images in parallel: a batch of consecutive images is converted to
//     luminance into contiguous buffers, then each image pair is scored by ssim_gray.
// Pass 2 needs the LDR/HDR decision and the BTF-wide peak (the fallback range of an all-zero
// image) that pass 1 finds, so they cannot be fused. Each image's own range (its reference
// luminance maximum) is found while its luminance is extracted.
//
// SSIM window rule, precisely. Per axis of n pixels the window radius is r = min(5, (n-1)/2),
// i.e. the window extent is 11 or, for n < 11, the largest odd size <= n (so a 17 x 7 image
// uses an 11 x 7 window and a 1 x 1 image a 1 x 1 window). The taps are exp(-k^2 / (2 sigma^2)),
// |k| <= r, sigma = 1.5 always, renormalised to sum 1 per axis. The SSIM map is averaged over
// the (w - 2 rx) x (h - 2 ry) positions where the window lies inside the image. For w, h >= 11
// this is exactly scikit-image's structural_similarity(gaussian_weights=True, sigma=1.5,
// use_sample_covariance=False, data_range=L) (its reflect-padded border is what it crops). A
// 1 x 1 pair gives (2ab + C1) / (a^2 + b^2 + C1): means are the values, variances 0.
// Degenerate input: w or h <= 0 returns 1 (nothing differs); L <= 0 or non-finite is taken as 1,
// so C1, C2 > 0 and constant or all-zero images never divide by zero (identical ones give 1).
#include "core/metrics.h"

#include "core/cpu_dispatch.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <vector>

namespace btfc {
namespace {

constexpr double k_sigma = 1.5;
constexpr int k_radius = 5;  // 11 x 11: scikit-image's int(3.5 * sigma + 0.5) for sigma 1.5
constexpr double k_k1 = 0.01, k_k2 = 0.03;
// Per-thread luminance buffer budget (two float images per batched image), batch cap and
// prefetch distance in texels. Measured on 128^2 and 256^2 x 81 x 81: with padded buffers (see
// mean_ssim) batches of 16 to 128 images cost about the same, 16 slightly least (-8 % CPU).
constexpr size_t k_batch_bytes = size_t(32) << 20;
constexpr size_t k_max_batch = 16;
constexpr size_t k_prefetch = 4;

std::vector<double> gaussian_taps(int r) {
  std::vector<double> g(size_t(2 * r + 1));
  double sum = 0;
  for (int k = -r; k <= r; ++k) sum += g[size_t(k + r)] = std::exp(-0.5 / (k_sigma * k_sigma) * double(k) * k);
  for (double& x : g) x /= sum;
  return g;
}

// The filters work on 8 adjacent columns at a time (then 1 for the tail), keeping the 8 x 5
// sums in vector registers while walking the taps. The vertical pass uses GCC/Clang vector
// types: written as a plain loop, GCC 12 spilled its sums to the stack (1.5x slower overall).
constexpr int k_lanes = 8;
typedef double v8d __attribute__((vector_size(64)));
typedef float v8f __attribute__((vector_size(32)));
struct Taps {
  const double* g;
  int n;
};

// Vertical pass for columns [x, x + 8): moments of a, b, a^2, b^2, ab over rows [0, taps.n)
// starting at ra / rb, written to the 5 maps of v (each w long).
inline void vertical8(const float* ra, const float* rb, int w, int x, const Taps& t, double* v) {
  v8d s[5] = {};
  for (int k = 0; k < t.n; ++k) {
    v8f fa, fb;
    std::memcpy(&fa, ra + size_t(k) * size_t(w) + size_t(x), sizeof fa);
    std::memcpy(&fb, rb + size_t(k) * size_t(w) + size_t(x), sizeof fb);
    const v8d p = __builtin_convertvector(fa, v8d), q = __builtin_convertvector(fb, v8d);
    const v8d gp = t.g[k] * p, gq = t.g[k] * q;
    s[0] += gp, s[1] += gq, s[2] += gp * p, s[3] += gq * q, s[4] += gp * q;
  }
  for (int m = 0; m < 5; ++m) std::memcpy(v + size_t(m) * size_t(w) + size_t(x), &s[m], sizeof s[m]);
}

// The same for the single column x.
inline void vertical1(const float* ra, const float* rb, int w, int x, const Taps& t, double* v) {
  double s[5] = {};
  for (int k = 0; k < t.n; ++k) {
    const double p = ra[size_t(k) * size_t(w) + size_t(x)], q = rb[size_t(k) * size_t(w) + size_t(x)];
    const double gp = t.g[k] * p, gq = t.g[k] * q;
    s[0] += gp, s[1] += gq, s[2] += gp * p, s[3] += gq * q, s[4] += gp * q;
  }
  for (int m = 0; m < 5; ++m) v[size_t(m) * size_t(w) + size_t(x)] = s[m];
}

// Horizontal pass for valid columns [x, x + V); adds their SSIM values to acc[0..V).
template <int V>
inline void horizontal_ssim(const double* v, int w, int x, const Taps& t, const double c[2], double* acc) {
  const double *va = v + x, *vb = va + w, *vaa = vb + w, *vbb = vaa + w, *vab = vbb + w;
  double u[5][V] = {};
  for (int k = 0; k < t.n; ++k) {
    const double g = t.g[k];
#pragma omp simd
    for (int j = 0; j < V; ++j) {
      u[0][j] += g * va[k + j], u[1][j] += g * vb[k + j], u[2][j] += g * vaa[k + j];
      u[3][j] += g * vbb[k + j], u[4][j] += g * vab[k + j];
    }
  }
#pragma omp simd
  for (int j = 0; j < V; ++j) {
    // Population (co)variances from the filtered moments, as Wang et al. and scikit-image.
    const double ua = u[0][j], ub = u[1][j];
    const double sa = u[2][j] - ua * ua, sb = u[3][j] - ub * ub, sab = u[4][j] - ua * ub;
    acc[j] += ((2 * ua * ub + c[0]) * (2 * sab + c[1])) / ((ua * ua + ub * ub + c[0]) * (sa + sb + c[1]));
  }
}

// Luminance of `cnt` consecutive images of one BTF, from image `first` on (adjacent in each
// ABRDF: btf.h's row order), into out[k * out_stride + texel]. Each texel lies in its own
// memory page, so its loads would wait for a TLB walk and a DRAM fetch before the next texel's
// could start: the batch's span of texel t + k_prefetch is prefetched.
void extract_luminance(const ImageView& first, size_t cnt, float* out, size_t out_stride) {
  const size_t n_tex = size_t(first.width) * size_t(first.height), stride = first.texel_stride;
  const size_t C = size_t(first.channels), span = cnt * C;
  float lum[k_max_batch];
  for (size_t t = 0; t < n_tex; ++t) {
    const float* p = first.base + t * stride;  // = &first.at(x, y, 0): texel t's image i0 + 0
    if (t + k_prefetch < n_tex)
      for (size_t o = 0; o < span; o += 16) __builtin_prefetch(p + k_prefetch * stride + o);
    if (C == 3) {
#pragma omp simd
      for (size_t k = 0; k < cnt; ++k) lum[k] = float(0.2126 * p[3 * k] + 0.7152 * p[3 * k + 1] + 0.0722 * p[3 * k + 2]);
    } else {
      for (size_t k = 0; k < cnt; ++k) lum[k] = p[k * C];
    }
    for (size_t k = 0; k < cnt; ++k) out[k * out_stride + t] = lum[k];
  }
}

// Maximum of n luminance values (-inf for n = 0).
float max_of(const float* y, size_t n) {
  float m = -std::numeric_limits<float>::infinity();
#pragma omp simd reduction(max : m)
  for (size_t i = 0; i < n; ++i) m = y[i] > m ? y[i] : m;
  return m;
}

// Mean SSIM over all (light, view) images of two same-shape BTFs. Dynamic range per image:
// `fixed_L` when > 0 (LDR data), else that reference image's luminance maximum, or `fallback_L`
// when the maximum is <= 0 (an all-zero / all-black image). core/metrics.h says why.
double mean_ssim(const Btf& ref, const Btf& test, double fixed_L, double fallback_L) {
  const BtfDesc& d = ref.desc();
  const size_t n_img = d.num_images(), n_tex = d.num_texels(), n_lights = d.num_lights();
  // Consecutive image indices (l + n_lights * v) are adjacent within each texel's ABRDF, so
  // extracting a batch of them texel by texel uses whole cache lines and pays each texel's page
  // walk once per batch; one image at a time would fetch a 64-byte line per texel for 3 floats.
  // Images in the buffers are padded 16 floats apart: with a power-of-two image size (256 x 256)
  // all of a texel's writes would land in one cache set (1.9x slower at batch 64, neutral at 16).
  const size_t ps = n_tex + 16;
  const size_t batch = std::clamp<size_t>(k_batch_bytes / (2 * sizeof(float) * ps), 1, k_max_batch);
  const long long n_batches = (long long)((n_img + batch - 1) / batch);
  std::vector<double> s(n_img);  // per image, summed serially: same result for any thread count
#pragma omp parallel
  {
    std::vector<float> ya(batch * ps), yb(batch * ps);
#pragma omp for schedule(dynamic)
    for (long long bi = 0; bi < n_batches; ++bi) {
      const size_t i0 = size_t(bi) * batch, cnt = std::min(batch, n_img - i0);
      extract_luminance(ref.image(i0 % n_lights, i0 / n_lights), cnt, ya.data(), ps);
      extract_luminance(test.image(i0 % n_lights, i0 / n_lights), cnt, yb.data(), ps);
      for (size_t k = 0; k < cnt; ++k) {
        double L = fixed_L;
        if (!(L > 0)) {
          const double mx = max_of(&ya[k * ps], n_tex);
          L = mx > 0 ? mx : fallback_L;
        }
        s[i0 + k] = ssim_gray(&ya[k * ps], &yb[k * ps], d.width, d.height, L);
      }
    }
  }
  double sum = 0;
  for (double v : s) sum += v;
  return sum / double(n_img);
}

}  // namespace

// Dispatched by CPU (core/cpu_dispatch.h): the v8d moments of vertical8 are one AVX-512 register,
// two AVX2 or four SSE2 ones; the portable build's baseline clone alone made `btfc compare` 1.36x
// slower (docs/benchmarks.md "Portable and native builds").
BTFC_CPU_CLONES double ssim_gray(const float* a, const float* b, int w, int h, double L) {
  if (w <= 0 || h <= 0) return 1.0;
  if (!(L > 0) || !std::isfinite(L)) L = 1.0;
  const double c1 = (k_k1 * L) * (k_k1 * L), c2 = (k_k2 * L) * (k_k2 * L);
  const int rx = std::min(k_radius, (w - 1) / 2), ry = std::min(k_radius, (h - 1) / 2);
  const std::vector<double> gx = gaussian_taps(rx), gy = gaussian_taps(ry);
  const int ow = w - 2 * rx, oh = h - 2 * ry;  // valid output positions

  // Row by row over the valid rows: the vertical pass gives the 5 filtered moments (a, b, a^2,
  // b^2, ab) of one row across the full width; the horizontal pass narrows them to the valid
  // columns and scores them. Nothing outside the valid region is filtered.
  std::vector<double> v(5 * size_t(w));
  const Taps tyy{gy.data(), 2 * ry + 1}, txx{gx.data(), 2 * rx + 1};
  const double c[2] = {c1, c2};
  double acc[k_lanes] = {}, tail = 0;  // per-lane sums of the SSIM map
  for (int y = 0; y < oh; ++y) {
    const float* ra = a + size_t(y) * size_t(w);
    const float* rb = b + size_t(y) * size_t(w);
    int x = 0;
    for (; x + k_lanes <= w; x += k_lanes) vertical8(ra, rb, w, x, tyy, v.data());
    for (; x < w; ++x) vertical1(ra, rb, w, x, tyy, v.data());
    for (x = 0; x + k_lanes <= ow; x += k_lanes) horizontal_ssim<k_lanes>(v.data(), w, x, txx, c, acc);
    for (; x < ow; ++x) horizontal_ssim<1>(v.data(), w, x, txx, c, &tail);
  }
  double sum = tail;
  for (double s : acc) sum += s;
  return sum / (double(ow) * double(oh));
}

Result<Metrics> compare_btf(const Btf& reference, const Btf& test, bool with_ssim) {
  const BtfDesc& d = reference.desc();
  const BtfDesc& e = test.desc();
  if (d.width != e.width || d.height != e.height || d.channels != e.channels ||
      d.num_lights() != e.num_lights() || d.num_views() != e.num_views())
    return invalid_argument("cannot compare BTFs of different shapes: reference is " + d.summary() + ", test is " +
                            e.summary());
  if (reference.size() == 0 || test.size() != reference.size())
    return invalid_argument("cannot compare empty BTFs (" + d.summary() + ")");

  // Pass 1: single streaming pass, texel by texel (each ABRDF is contiguous).
  const long long n_tex = (long long)d.num_texels();
  const size_t n_row = d.abrdf_size();
  double sq_err = 0, sq_ref = 0, max_abs = 0, max_ref = -std::numeric_limits<double>::infinity();
#pragma omp parallel for schedule(static) reduction(+ : sq_err, sq_ref) reduction(max : max_abs, max_ref)
  for (long long t = 0; t < n_tex; ++t) {
    const float* pa = reference.abrdf(size_t(t));
    const float* pb = test.abrdf(size_t(t));
    double te = 0, tr = 0, tm = 0, tx = -std::numeric_limits<double>::infinity();
#pragma omp simd reduction(+ : te, tr) reduction(max : tm, tx)
    for (size_t i = 0; i < n_row; ++i) {
      const double ra = pa[i], diff = ra - double(pb[i]);
      te += diff * diff;
      tr += ra * ra;
      const double ad = std::fabs(diff);  // maxima as selects, which GCC vectorises
      tm = ad > tm ? ad : tm;
      tx = ra > tx ? ra : tx;
    }
    sq_err += te;
    sq_ref += tr;
    max_abs = std::max(max_abs, tm);
    max_ref = std::max(max_ref, tx);
  }

  Metrics m;
  m.rmse = std::sqrt(sq_err / double(reference.size()));
  const double inf = std::numeric_limits<double>::infinity();
  // ||a|| == 0: b == 0 exactly when the error is 0 too.
  m.rel_l2 = sq_ref > 0 ? std::sqrt(sq_err / sq_ref) : (sq_err == 0 ? 0.0 : inf);
  m.max_abs = max_abs;
  // LDR data from 8-bit sources spans [0, 1] whatever this particular image's maximum is.
  const bool ldr = !d.hdr && max_ref <= 1.0;
  m.peak = ldr ? 1.0 : (max_ref > 0 ? max_ref : 1.0);
  m.psnr = m.rmse == 0 ? inf : 20.0 * std::log10(m.peak / m.rmse);
  m.ssim_range = ldr ? Metrics::SsimRange::ldr_one : Metrics::SsimRange::per_image_max;
  if (with_ssim) m.mean_ssim = mean_ssim(reference, test, ldr ? 1.0 : 0.0, m.peak);  // else left at the default
  return m;
}

}  // namespace btfc
