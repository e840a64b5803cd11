// mlvq noise-adaptive SSIM thresholds; contract in mlvq_internal.h (estimate_noise,
// noise_ceilings).
//
// Why: the leader VQ reuses an entry when SSIM >= the level's threshold. Two noisy measurements
// of one and the same signal do not reach SSIM 1: with signal variance s2 and noise variance n2
// per value, their expected structure-contrast term is (2 s2 + C2) / (2 s2 + 2 n2 + C2). A
// threshold above that "noise ceiling" makes every noisy vector a new entry (the codebooks grow
// with the number of vectors, the file grows and the quadratic search slows down) while the
// extra entries only store noise. So each level's threshold is capped at the median ceiling of
// that level's vectors: an entry is reused when it differs from a vector by no more than two
// noisy copies of one signal typically do. On clean data the ceilings are ~1 and the user's
// thresholds apply unchanged.
//
// The noise is estimated per (light, view) image from the data, not assumed: Donoho's robust
// estimator, sigma = median(|HH|) / 0.6745 over the finest diagonal Haar details of the image
// (2 x 2 texel blocks). Alone it reads texture at the texel scale as noise (a speckled albedo
// made every synthetic BTF "noisy" and the default over-compressed it: MSSIM 0.77 at 4000:1).
// What tells the two apart is that texture repeats from image to image and noise does not: the
// same light seen from the nearest other view (the nearest other light for a one-view BTF) has
// the same albedo detail, scaled, but independent noise (camera noise, or a renderer's samples,
// which a view's images may share between lights but not between views). So the details of that
// partner image, scaled to the same median magnitude k and subtracted (either sign: relief can
// flip the detail's sign), leave sqrt(2) sigma of noise and no shared texture:
// sigma_pair = median(|HH_i -+ k HH_j|) / (0.6745 sqrt 2). Where the detail does not repeat
// (parallax, shadows moving between views) the difference is large, so the estimate is the
// smaller of the two: the pair can only lower Donoho's, never raise it. Resampling to the grid
// blends 9 measured images with weights w_j, so a grid node's noise variance is
// sum_j w_j^2 sigma_j^2.
#include <algorithm>
#include <cmath>

#include "codecs/mlvq/mlvq_internal.h"

namespace btfc::mlvq {

namespace {

double median_of(std::vector<float>& v) {
  if (v.empty()) return 0;
  auto mid = v.begin() + std::ptrdiff_t(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  return double(*mid);
}

// median |h| of one image's signed details.
double median_abs(const float* h, size_t n) {
  std::vector<float> v(n);
  for (size_t b = 0; b < n; ++b) v[b] = std::fabs(h[b]);
  return median_of(v);
}

// Robust sigma of image i's details h_i against its partner's h_j: Donoho's, or lower where the
// detail repeats in the partner (see the top of this file).
double pair_sigma(const float* hi, const float* hj, size_t n) {
  const double mi = median_abs(hi, n), mj = median_abs(hj, n), donoho = mi / 0.6745;
  if (!(mj > 0) || hi == hj) return donoho;
  const float k = float(mi / mj);
  double best = donoho;
  std::vector<float> v(n);
  for (float sgn : {1.0f, -1.0f}) {
    for (size_t b = 0; b < n; ++b) v[b] = std::fabs(hi[b] - sgn * k * hj[b]);
    best = std::min(best, median_of(v) / (0.6745 * std::sqrt(2.0)));
  }
  return best;
}

// Image index (light + lights x view) of image i's partner: the same light from the nearest other
// view, or for one view the nearest other light; i itself when there is no other.
size_t partner_image(const BtfDesc& d, size_t i) {
  const size_t nl = d.num_lights(), l = i % nl, v = i / nl;
  const bool by_view = d.num_views() > 1;
  const std::vector<Vec3>& dirs = by_view ? d.views.dirs : d.lights.dirs;
  const size_t self = by_view ? v : l;
  size_t best = self;
  double best_dot = -2;
  for (size_t k = 0; k < dirs.size(); ++k) {
    if (k == self) continue;
    const double dot = double(dirs[k].x) * dirs[self].x + double(dirs[k].y) * dirs[self].y + double(dirs[k].z) * dirs[self].z;
    if (dot > best_dot) best_dot = dot, best = k;
  }
  return by_view ? l + nl * best : best + nl * v;
}

}  // namespace

NoiseEstimate estimate_noise(const Btf& btf, size_t max_blocks) {
  const BtfDesc& d = btf.desc();
  const size_t ni = d.num_images(), nc = size_t(d.channels);
  NoiseEstimate ne;
  ne.lum_var.assign(ni, 0.f);
  ne.chroma_var.assign(ni, 0.f);
  const size_t bw = size_t(d.width) / 2, bh = size_t(d.height) / 2;
  if (bw == 0 || bh == 0) return ne;  // no 2 x 2 block: no estimate, no adaptation
  // Blocks on a regular sub-grid, at most max_blocks (a median of ~1000 samples is within a few %).
  const size_t step = std::max<size_t>(1, size_t(std::ceil(std::sqrt(double(bw * bh) / double(std::max<size_t>(max_blocks, 1))))));
  std::vector<std::pair<size_t, size_t>> blocks;
  for (size_t by = 0; by < bh; by += step)
    for (size_t bx = 0; bx < bw; bx += step) blocks.push_back({2 * bx, 2 * by});
  const size_t nb = blocks.size();
  // HH (signed) per image and block for L, r and g (image-major so each image's median is one run).
  std::vector<float> hl(ni * nb), hr(ni * nb), hg(ni * nb);
#pragma omp parallel for schedule(static)
  for (size_t b = 0; b < nb; ++b) {
    const auto [x, y] = blocks[b];
    const float* t[4] = {btf.abrdf(x + size_t(d.width) * y), btf.abrdf(x + 1 + size_t(d.width) * y),
                         btf.abrdf(x + size_t(d.width) * (y + 1)), btf.abrdf(x + 1 + size_t(d.width) * (y + 1))};
    const float sign[4] = {0.5f, -0.5f, -0.5f, 0.5f};
    for (size_t i = 0; i < ni; ++i) {
      float dl = 0, dr = 0, dg = 0;
      for (int k = 0; k < 4; ++k) {
        const float* p = t[k] + nc * i;
        float rgb[3] = {p[0], nc == 3 ? p[1] : p[0], nc == 3 ? p[2] : p[0]}, lrg[3];
        rgb_to_lrg(rgb, lrg);
        dl += sign[k] * lrg[0], dr += sign[k] * lrg[1], dg += sign[k] * lrg[2];
      }
      hl[i * nb + b] = dl, hr[i * nb + b] = dr, hg[i * nb + b] = dg;
    }
  }
#pragma omp parallel for schedule(static)
  for (size_t i = 0; i < ni; ++i) {
    const size_t j = partner_image(d, i);
    const double sl = pair_sigma(&hl[i * nb], &hl[j * nb], nb);
    const double sr = pair_sigma(&hr[i * nb], &hr[j * nb], nb);
    const double sg = pair_sigma(&hg[i * nb], &hg[j * nb], nb);
    ne.lum_var[i] = float(sl * sl);
    ne.chroma_var[i] = float(0.5 * (sr * sr + sg * sg));
  }
  return ne;
}

NoiseCeilings noise_ceilings(const Btf& btf, const ResamplePlan& plan, const NoiseEstimate& ne, size_t sample_texels) {
  const Grid& g = plan.grid;
  const size_t G = g.size(), N = btf.desc().num_texels(), nc = size_t(plan.channels);
  NoiseCeilings c;
  if (N == 0 || ne.lum_var.empty()) return c;
  // Per node: noise variance of L and of (r, g) after resampling (sum of w^2 sigma^2).
  std::vector<float> nl(G), ncr(G);
  for (size_t node = 0; node < G; ++node) {
    double a = 0, b = 0;
    for (int j = 0; j < 9; ++j) {
      const size_t img = plan.off[node][size_t(j)] / nc;
      const double w2 = double(plan.w[node][size_t(j)]) * plan.w[node][size_t(j)];
      a += w2 * ne.lum_var[img], b += w2 * ne.chroma_var[img];
    }
    nl[node] = float(a), ncr[node] = float(b);
  }
  const size_t S = std::min(N, std::max<size_t>(sample_texels, 1)), step = N / S;
  std::vector<float> ql[5], qc[5];
  std::vector<float> lum(G), chroma(2 * G);
  for (size_t s = 0; s < S; ++s) {
    extract(plan, btf.abrdf(s * step), 0, G, lum.data(), chroma.data());
    for (int k = 1; k <= 4; ++k) {
      const size_t len = g.slice_len(k);
      for (size_t f = 0; f + len <= G; f += len) {
        double sx = 0, sxx = 0, peak = 0, sn = 0, cx = 0, cxx = 0, cn = 0;
        for (size_t i = f; i < f + len; ++i) {
          sx += lum[i], sxx += double(lum[i]) * lum[i], peak = std::max(peak, double(lum[i])), sn += nl[i];
          cx += chroma[2 * i] + chroma[2 * i + 1];
          cxx += double(chroma[2 * i]) * chroma[2 * i] + double(chroma[2 * i + 1]) * chroma[2 * i + 1];
          cn += ncr[i];
        }
        const double n = double(len);
        if (peak > 0) {  // zero slices are matched exactly, they say nothing about noise
          const double vx = std::max(0.0, sxx / n - (sx / n) * (sx / n)), vn = sn / n, vs = std::max(0.0, vx - vn);
          const double c2 = (0.03 * peak) * (0.03 * peak);
          ql[k].push_back(float((2 * vs + c2) / (2 * vs + 2 * vn + c2)));
        }
        const double vx = std::max(0.0, cxx / (2 * n) - (cx / (2 * n)) * (cx / (2 * n))), vn = cn / n, vs = std::max(0.0, vx - vn);
        const double c2 = 0.03 * 0.03;  // chromaticity SSIM uses the range 1
        qc[k].push_back(float((2 * vs + c2) / (2 * vs + 2 * vn + c2)));
      }
    }
  }
  for (int k = 1; k <= 4; ++k) {
    c.lum[k] = ql[k].empty() ? 1.0 : median_of(ql[k]);
    c.chroma[k] = qc[k].empty() ? 1.0 : median_of(qc[k]);
  }
  return c;
}

}  // namespace btfc::mlvq
