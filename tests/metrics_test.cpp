// Metrics tests: identical inputs, hand-computed RMSE/PSNR/relative L2, SSIM pinned against
// scikit-image, the PSNR peak rule, shape mismatch errors and mean SSIM over a BTF's images.
#include "core/metrics.h"

#include <gtest/gtest.h>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <vector>

namespace btfc {
namespace {

constexpr double k_inf = std::numeric_limits<double>::infinity();

DirectionSet ring(int n) {
  DirectionSet s;
  for (int i = 0; i < n; ++i) s.dirs.push_back(dir_from_theta_phi(0.5, 6.283185307179586 * i / n));
  s.identify();
  return s;
}

BtfDesc make_desc(int w, int h, int lights, int views, int channels = 3, bool hdr = false) {
  BtfDesc d;
  d.width = w;
  d.height = h;
  d.channels = channels;
  d.lights = ring(lights);
  d.views = ring(views);
  d.hdr = hdr;
  return d;
}

Btf make_btf(const BtfDesc& d) {
  auto r = Btf::create(d);
  EXPECT_TRUE(r.ok()) << r.status().message();
  return std::move(r).value();
}

// Fills every value with a smooth deterministic pattern in [0.1, 0.9] (+ `offset` pattern).
void fill(Btf& btf, double wobble) {
  const BtfDesc& d = btf.desc();
  for (int y = 0; y < d.height; ++y)
    for (int x = 0; x < d.width; ++x)
      for (size_t v = 0; v < d.num_views(); ++v)
        for (size_t l = 0; l < d.num_lights(); ++l)
          for (int c = 0; c < d.channels; ++c)
            btf.at(x, y, l, v, c) = float(0.5 + 0.3 * std::sin(0.4 * x + 0.9 * l + 0.3 * c) * std::cos(0.3 * y + 0.7 * v) +
                                          wobble * std::sin(1.7 * x - 0.8 * y + 2.1 * l + 1.3 * v + 0.5 * c));
}

TEST(Metrics, IdenticalBtfs) {
  Btf a = make_btf(make_desc(16, 12, 3, 2));
  fill(a, 0.05);
  auto m = compare_btf(a, a);
  ASSERT_TRUE(m.ok()) << m.status().message();
  EXPECT_EQ(m->rmse, 0.0);
  EXPECT_EQ(m->rel_l2, 0.0);
  EXPECT_EQ(m->max_abs, 0.0);
  EXPECT_EQ(m->psnr, k_inf);
  EXPECT_EQ(m->peak, 1.0);
  EXPECT_NEAR(m->mean_ssim, 1.0, 1e-12);
}

TEST(Metrics, IdenticalAllZeroBtfs) {
  Btf a = make_btf(make_desc(12, 12, 2, 1));
  auto m = compare_btf(a, a);
  ASSERT_TRUE(m.ok());
  EXPECT_EQ(m->rmse, 0.0);
  EXPECT_EQ(m->rel_l2, 0.0);
  EXPECT_EQ(m->psnr, k_inf);
  EXPECT_EQ(m->peak, 1.0);
  EXPECT_NEAR(m->mean_ssim, 1.0, 1e-12);
  // ||a|| = 0 but b != 0: relative error is unbounded.
  Btf b = make_btf(a.desc());
  b.at(3, 4, 1, 0, 2) = 0.25f;
  auto n = compare_btf(a, b, false);
  ASSERT_TRUE(n.ok());
  EXPECT_EQ(n->rel_l2, k_inf);
}

TEST(Metrics, KnownRmsePsnrByHand) {
  // 2 x 2 texels, 1 light, 1 view, RGB: 12 values, reference all 0.5. Four values of the test
  // differ by +0.1, +0.1, -0.1, +0.3: sum of squares 0.12, MSE 0.01, RMSE 0.1,
  // PSNR 20 log10(1 / 0.1) = 20 dB, ||a||^2 = 12 * 0.25 = 3, rel L2 sqrt(0.12 / 3) = 0.2.
  Btf a = make_btf(make_desc(2, 2, 1, 1));
  for (size_t i = 0; i < a.size(); ++i) a.data()[i] = 0.5f;
  Btf b = a;
  b.at(0, 0, 0, 0, 0) = 0.6f;
  b.at(1, 0, 0, 0, 1) = 0.6f;
  b.at(0, 1, 0, 0, 2) = 0.4f;
  b.at(1, 1, 0, 0, 0) = 0.8f;
  auto m = compare_btf(a, b, false);
  ASSERT_TRUE(m.ok());
  EXPECT_NEAR(m->rmse, 0.1, 1e-7);
  EXPECT_NEAR(m->psnr, 20.0, 1e-5);
  EXPECT_NEAR(m->rel_l2, 0.2, 1e-7);
  EXPECT_NEAR(m->max_abs, 0.3, 1e-7);
  EXPECT_EQ(m->peak, 1.0);
  EXPECT_EQ(m->mean_ssim, Metrics{}.mean_ssim);  // not computed: left at its default
}

// --- SSIM pinned against scikit-image ------------------------------------------------------
// Each pair mirrors scripts/ssim_reference.py (same formulas, double math, rounded to float;
// i = row, j = column).

double f_smooth(int i, int j) { return 0.5 + 0.4 * std::sin(0.37 * i) * std::cos(0.23 * j); }
double f_odd(int i, int j) { return 0.5 + 0.3 * std::sin(0.51 * i + 0.17 * j) + 0.1 * std::cos(0.83 * j); }
double f_hdr(int i, int j) { return 500.0 + 450.0 * std::sin(0.21 * i) * std::cos(0.33 * j); }
double f_wave(int i, int j) { return 0.5 + 0.45 * std::sin(2.7 * i + 1.9 * j); }

struct Pair {
  const char* name;
  int h, w;
  std::function<double(int, int)> fa, fb;
  double L;
  double expected;
};

std::vector<float> make_image(int h, int w, const std::function<double(int, int)>& f) {
  std::vector<float> img(size_t(h) * w);
  for (int i = 0; i < h; ++i)
    for (int j = 0; j < w; ++j) img[size_t(i) * w + j] = float(f(i, j));
  return img;
}

TEST(Metrics, SsimPinnedAgainstScikitImage) {
  auto odd_b = [](int i, int j) { return 0.9 * f_odd(i, j) + 0.03 * std::sin(2.1 * i) * std::cos(1.7 * j); };
  auto noise_b = [](int i, int j) { return f_smooth(i, j) + 0.05 * std::sin(1.3 * i + 0.7 * j); };
  // Expected values printed by scripts/ssim_reference.py with scikit-image 0.19.3 (numpy 1.24.2,
  // Debian python3-skimage): structural_similarity(a, b, gaussian_weights=True, sigma=1.5,
  // use_sample_covariance=False, data_range=L) on the float32 images promoted to float64.
  // The last three pairs are smaller than 11 x 11, which scikit-image rejects; their values come
  // from the same script's numpy implementation of the clipped-window rule (core/metrics.cpp),
  // which the script checks against scikit-image to 1e-12 on the six large pairs.
  const std::vector<Pair> pairs = {
      {"noise", 48, 64, f_smooth, noise_b, 1.0, 0.9502131442001239},
      {"contrast", 40, 40, f_smooth, [](int i, int j) { return 0.25 + 0.5 * f_smooth(i, j); }, 1.0, 0.798166629555912},
      {"odd_17x23", 17, 23, f_odd, odd_b, 1.0, 0.9837485869889468},
      {"hdr", 29, 32, f_hdr, [](int i, int j) { return f_hdr(i, j) + 40.0 * std::sin(0.9 * i + 1.1 * j); }, 1000.0,
       0.9698795167671492},
      {"phase", 24, 24, f_wave, [](int i, int j) { return 0.5 + 0.45 * std::sin(2.7 * i + 1.9 * j + 0.8); }, 1.0,
       0.698048391457911},
      {"inverted", 20, 30, f_smooth, [](int i, int j) { return 1.0 - f_smooth(i, j); }, 1.0, -0.779290918026386},
      {"small_7x9", 7, 9, f_odd, odd_b, 1.0, 0.9826789249641511},
      {"thin_5x30", 5, 30, f_smooth, noise_b, 1.0, 0.9466518164959867},
      {"column_30x1", 30, 1, f_odd, [](int i, int j) { return 0.8 * f_odd(i, j) + 0.05; }, 1.0, 0.9700225704754025},
  };
  for (const Pair& p : pairs) {
    const std::vector<float> a = make_image(p.h, p.w, p.fa), b = make_image(p.h, p.w, p.fb);
    EXPECT_NEAR(ssim_gray(a.data(), b.data(), p.w, p.h, p.L), p.expected, 1e-6) << p.name;
    EXPECT_NEAR(ssim_gray(a.data(), a.data(), p.w, p.h, p.L), 1.0, 1e-12) << p.name;
  }
}

TEST(Metrics, SsimConstantAndTinyImages) {
  // Constant images: variances 0, so SSIM = (2ab + C1) / (a^2 + b^2 + C1) with C1 = 1e-4 (L = 1).
  const std::vector<float> zero(15 * 13, 0.0f), c2(15 * 13, 0.2f), c6(15 * 13, 0.6f);
  EXPECT_EQ(ssim_gray(zero.data(), zero.data(), 15, 13, 1.0), 1.0);
  EXPECT_NEAR(ssim_gray(c2.data(), c2.data(), 15, 13, 1.0), 1.0, 1e-12);
  const double a = double(0.2f), b = double(0.6f);
  EXPECT_NEAR(ssim_gray(c2.data(), c6.data(), 15, 13, 1.0), (2 * a * b + 1e-4) / (a * a + b * b + 1e-4), 1e-12);
  // 1 x 1: the single pixel pair, mean = value, variance 0.
  const float p = 0.3f, q = 0.7f;
  EXPECT_NEAR(ssim_gray(&p, &q, 1, 1, 1.0), (2.0 * p * q + 1e-4) / (double(p) * p + double(q) * q + 1e-4), 1e-12);
  // Degenerate arguments never give NaN.
  EXPECT_EQ(ssim_gray(zero.data(), zero.data(), 15, 13, 0.0), 1.0);
  EXPECT_EQ(ssim_gray(nullptr, nullptr, 0, 0, 1.0), 1.0);
}

// --- peak rule ------------------------------------------------------------------------------

TEST(Metrics, PeakRule) {
  struct Case {
    bool hdr;
    float max_value;
    double expected_peak;
  };
  // LDR flag and max <= 1: peak 1 regardless of the data max. A value > 1 or the hdr flag:
  // the reference maximum. Max <= 0 with hdr: 1.
  for (const Case& c : {Case{false, 0.8f, 1.0}, Case{false, 1.0f, 1.0}, Case{false, 4.0f, 4.0},
                        Case{true, 0.5f, 0.5}, Case{true, 1000.0f, 1000.0}, Case{true, 0.0f, 1.0}, Case{true, -2.0f, 1.0}}) {
    Btf a = make_btf(make_desc(12, 11, 2, 1, 3, c.hdr));
    for (size_t i = 0; i < a.size(); ++i) a.data()[i] = c.max_value * float(0.5 + 0.5 * std::sin(0.1 * double(i)));
    a.at(5, 5, 1, 0, 1) = c.max_value;
    Btf b = a;
    for (size_t i = 0; i < b.size(); i += 7) b.data()[i] += 0.01f * std::fabs(c.max_value) + 0.001f;
    auto m = compare_btf(a, b);
    ASSERT_TRUE(m.ok());
    EXPECT_DOUBLE_EQ(m->peak, c.expected_peak) << c.hdr << " " << c.max_value;
    EXPECT_NEAR(m->psnr, 20.0 * std::log10(c.expected_peak / m->rmse), 1e-9);
    // SSIM range: 1 for LDR data; for HDR data each reference image's luminance maximum, the
    // BTF-wide peak when that is <= 0.
    const bool ldr = !c.hdr && c.max_value <= 1.0f;
    EXPECT_EQ(m->ssim_range, ldr ? Metrics::SsimRange::ldr_one : Metrics::SsimRange::per_image_max);
    std::vector<float> ya(a.desc().num_texels()), yb(ya.size());
    double sum = 0;
    for (size_t l = 0; l < 2; ++l) {
      for (int y = 0; y < 11; ++y)
        for (int x = 0; x < 12; ++x) {
          ya[x + 12 * y] = float(0.2126 * a.at(x, y, l, 0, 0) + 0.7152 * a.at(x, y, l, 0, 1) + 0.0722 * a.at(x, y, l, 0, 2));
          yb[x + 12 * y] = float(0.2126 * b.at(x, y, l, 0, 0) + 0.7152 * b.at(x, y, l, 0, 1) + 0.0722 * b.at(x, y, l, 0, 2));
        }
      double L = 1.0;
      if (!ldr) {
        const double mx = *std::max_element(ya.begin(), ya.end());
        L = mx > 0 ? mx : c.expected_peak;
      }
      sum += ssim_gray(ya.data(), yb.data(), 12, 11, L);
    }
    EXPECT_NEAR(m->mean_ssim, sum / 2, 1e-12);
  }
}

// Two-sided check of the per-image range against scikit-image: one HDR image (the "hdr" pair of
// scripts/ssim_reference.py) as a 1-light, 1-view, 1-channel BTF. scikit-image 0.19.3 with
// data_range = the reference's maximum (947.716) gives 0.9697431350360517 ("hdr_own_range");
// the global-range value of the same pair at L = 1000 is 0.9698795, so a tolerance of 1e-6
// tells the two rules apart.
TEST(Metrics, HdrSsimUsesEachImagesMaximumLikeScikitImage) {
  const int h = 29, w = 32;
  Btf a = make_btf(make_desc(w, h, 1, 1, 1, true));
  Btf b = make_btf(a.desc());
  for (int i = 0; i < h; ++i)
    for (int j = 0; j < w; ++j) {
      a.at(j, i, 0, 0, 0) = float(f_hdr(i, j));
      b.at(j, i, 0, 0, 0) = float(f_hdr(i, j) + 40.0 * std::sin(0.9 * i + 1.1 * j));
    }
  auto m = compare_btf(a, b);
  ASSERT_TRUE(m.ok());
  EXPECT_EQ(m->ssim_range, Metrics::SsimRange::per_image_max);
  EXPECT_NEAR(m->mean_ssim, 0.9697431350360517, 1e-6);
  // Two images of very different brightness: each is scored against its own range, so a dim
  // image's error counts as much as a bright one's (a global range would hide it).
  Btf c = make_btf(make_desc(w, h, 2, 1, 1, true));
  Btf d = make_btf(c.desc());
  for (int i = 0; i < h; ++i)
    for (int j = 0; j < w; ++j)
      for (size_t l = 0; l < 2; ++l) {
        const double s = l == 0 ? 1.0 : 0.01;
        c.at(j, i, l, 0, 0) = float(s * f_hdr(i, j));
        d.at(j, i, l, 0, 0) = float(s * (f_hdr(i, j) + 40.0 * std::sin(0.9 * i + 1.1 * j)));
      }
  auto n = compare_btf(c, d);
  ASSERT_TRUE(n.ok());
  EXPECT_NEAR(n->mean_ssim, 0.9697431350360517, 1e-5);
}

// --- errors ---------------------------------------------------------------------------------

TEST(Metrics, ShapeMismatchNamesBothShapes) {
  const Btf a = make_btf(make_desc(8, 6, 3, 2));
  for (const BtfDesc& d : {make_desc(6, 8, 3, 2), make_desc(8, 6, 2, 3), make_desc(8, 6, 3, 1), make_desc(8, 6, 3, 2, 1)}) {
    const Btf b = make_btf(d);
    auto m = compare_btf(a, b);
    ASSERT_FALSE(m.ok());
    EXPECT_EQ(m.status().code(), StatusCode::invalid_argument);
    EXPECT_NE(m.status().message().find(a.desc().summary()), std::string::npos) << m.status().message();
    EXPECT_NE(m.status().message().find(d.summary()), std::string::npos) << m.status().message();
  }
  auto e = compare_btf(Btf{}, Btf{});
  EXPECT_EQ(e.status().code(), StatusCode::invalid_argument);
}

// --- mean SSIM over a BTF -------------------------------------------------------------------

// Mean of ssim_gray over every (light, view) luminance image (first channel unless RGB).
double reference_mean_ssim(const Btf& a, const Btf& b, double L) {
  const BtfDesc& d = a.desc();
  std::vector<float> ya(d.num_texels()), yb(d.num_texels());
  auto lum = [&](const Btf& t, int x, int y, size_t l, size_t v) {
    if (d.channels != 3) return t.at(x, y, l, v, 0);
    return float(0.2126 * t.at(x, y, l, v, 0) + 0.7152 * t.at(x, y, l, v, 1) + 0.0722 * t.at(x, y, l, v, 2));
  };
  double sum = 0;
  for (size_t v = 0; v < d.num_views(); ++v)
    for (size_t l = 0; l < d.num_lights(); ++l) {
      for (int y = 0; y < d.height; ++y)
        for (int x = 0; x < d.width; ++x) {
          ya[x + size_t(d.width) * y] = lum(a, x, y, l, v);
          yb[x + size_t(d.width) * y] = lum(b, x, y, l, v);
        }
      sum += ssim_gray(ya.data(), yb.data(), d.width, d.height, L);
    }
  return sum / double(d.num_images());
}

TEST(Metrics, MeanSsimIsAverageOfImageSsims) {
  // 9 x 8 = 72 images: several extraction batches (at most 16 images), the last partial.
  for (int channels : {3, 1, 2}) {
    Btf a = make_btf(make_desc(13, 11, 9, 8, channels));
    Btf b = make_btf(a.desc());
    fill(a, 0.0);
    fill(b, 0.08);
    auto m = compare_btf(a, b);
    ASSERT_TRUE(m.ok());
    const double expected = reference_mean_ssim(a, b, 1.0);
    EXPECT_NEAR(m->mean_ssim, expected, 1e-12) << channels;
    EXPECT_LT(m->mean_ssim, 0.999);
    EXPECT_GT(m->mean_ssim, 0.0);
    // Images are scored independently and summed in order: thread count does not matter.
    const int threads = omp_get_max_threads();
    omp_set_num_threads(1);
    auto m1 = compare_btf(a, b);
    omp_set_num_threads(threads);
    ASSERT_TRUE(m1.ok());
    EXPECT_EQ(m1->mean_ssim, m->mean_ssim);
    EXPECT_NEAR(m1->rmse, m->rmse, 1e-15);
  }
}

}  // namespace
}  // namespace btfc
