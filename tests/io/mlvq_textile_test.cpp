// mlvq on realistic HDR data (issue 22): texel crops of the textile
// (../shared/data/textile_lurex_utia64: full 81 x 81 directions, HDR, Monte Carlo noise,
// highlights 450x the median). The data is always present beside the repository: a missing
// folder fails. Two-sided bounds measured from the code (0.75 x bound <= value <= bound): a
// change that makes the codec much better must update them as much as one that makes it worse.
// The full-textile figures (and the encode-time goals) are benchmarks: docs/benchmarks.md.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>

#include "codecs/mlvq/mlvq.h"
#include "codecs/mlvq/mlvq_internal.h"
#include "core/metrics.h"
#include "formats/image_set.h"
#include "tests/test_paths.h"

using namespace btfc;

namespace {

const Btf& textile() {
  static Btf full = [] {
    const std::string dir = std::string(BTFC_DATA_DIR) + "/textile_lurex_utia64";
    auto f = read_image_set(dir);
    EXPECT_TRUE(f.ok()) << f.status().message();
    return f.ok() ? std::move(f).value() : Btf();
  }();
  return full;
}

Btf crop(int x0, int y0, int n) {
  const Btf& full = textile();
  BtfDesc d = full.desc();
  d.width = d.height = n;
  auto c = Btf::create(d);
  EXPECT_TRUE(c.ok());
  for (int y = 0; y < n; ++y)
    for (int x = 0; x < n; ++x)
      std::copy_n(full.abrdf(size_t(x0 + x) + size_t(full.desc().width) * size_t(y0 + y)), d.abrdf_size(), c->abrdf(size_t(x + n * y)));
  return std::move(c).value();
}

const Btf& textile_crop() {
  static Btf c = crop(24, 24, 8);
  return c;
}

bool have_data() { return std::filesystem::exists(std::string(BTFC_DATA_DIR) + "/textile_lurex_utia64/README.md") ||
                          std::filesystem::exists(std::string(BTFC_DATA_DIR) + "/textile_lurex_utia64"); }

// `b` encoded with the mlvq spec `text`.
Result<std::unique_ptr<Model>> encode(const Btf& b, const std::string& text) {
  BTFC_ASSIGN_OR_RETURN(auto spec, parse_spec_string(text));
  BTFC_ASSIGN_OR_RETURN(Params p, bind_params(spec, mlvq_codec().params()));
  Context ctx;
  return mlvq_codec().encode(b, p, ctx);
}

double stat(const Model& m, const std::string& key) {
  for (const auto& [k, v] : m.stats().numbers)
    if (k == key) return v;
  return NAN;
}
// Float32 bytes of the BTF / payload bytes: bench's ratio (mlvq's stats no longer repeat it).
double payload_ratio(const Model& m) { return double(m.desc().num_values()) * 4.0 / double(m.payload_bytes()); }

void in_band(double v, double bound, const char* what) {
  EXPECT_LE(v, bound) << what;
  EXPECT_GE(v, 0.75 * bound) << what;
}

}  // namespace

TEST(MlvqTextile, GridLayoutCropIsBoundedByItsResampling) {
  ASSERT_TRUE(have_data()) << "../shared/data/textile_lurex_utia64 is missing";
  const Btf& b = textile_crop();
  // The paper's grid layout (small grid) with the previous defaults: what bounds its quality.
  auto m = encode(b, "mlvq:scheme=4:phi=8:theta=4:alpha=7:beta=7:ssim4=0.9:ssim3=0.9:ssim2=0.95:ssim1=0.98:chroma=1:"
                     "value_bits=0:scale_bits=16:noise=off");
  ASSERT_TRUE(m.ok()) << m.status().message();
  Btf out;
  ASSERT_TRUE(m.value()->decode_all(out).ok());
  double num = 0, den = 0;
  for (size_t i = 0; i < b.size(); ++i) {
    const double e = double(out.data()[i]) - b.data()[i];
    num += e * e, den += double(b.data()[i]) * b.data()[i];
  }
  const double rel = std::sqrt(num / den);
  const double ratio = payload_ratio(*m.value());
  const double lum1 = stat(*m.value(), "bytes.lum1.values") / stat(*m.value(), "payload_bytes");
  // Measured: rel_l2 0.763 (resampling alone 0.742), 95.7 : 1, level-1 luminance 42 % of the bytes.
  std::printf("rel_l2 %.4f ratio %.2f texel_ssim %.4f resample %.4f lum1_share %.3f\n", rel, ratio, stat(*m.value(), "mean_texel_ssim"),
              stat(*m.value(), "resample_rel_rmse"), lum1);
  in_band(rel, 0.80, "relative L2 error");
  in_band(ratio, 100.0, "ratio vs float32");
  in_band(stat(*m.value(), "resample_rel_rmse"), 0.78, "resampling error alone");
  // What fills the payload on this noisy HDR data: the level-1 luminance values.
  in_band(lum1, 0.45, "share of the level-1 luminance values in the payload");
}

TEST(MlvqTextile, NoiseCeilingsOfTheTextileAreMeasuredAndBindOnlyWhenBelowTheThresholds) {
  ASSERT_TRUE(have_data()) << "../shared/data/textile_lurex_utia64 is missing";
  const Btf& b = textile_crop();
  mlvq::Grid g;
  g.nphi = 8, g.ntheta = 4, g.nalpha = 7, g.nbeta = 7;
  const mlvq::NoiseEstimate ne = mlvq::estimate_noise(b);
  double mean_var = 0;
  for (float v : ne.lum_var) mean_var += v;
  mean_var /= double(ne.lum_var.size());
  const mlvq::NoiseCeilings c = mlvq::noise_ceilings(b, mlvq::make_plan(b.desc(), g), ne);
  std::printf("mean lum noise var %.4g ceilings lum %.4f %.4f %.4f %.4f chroma %.4f %.4f %.4f %.4f\n", mean_var, c.lum[1], c.lum[2], c.lum[3],
              c.lum[4], c.chroma[1], c.chroma[2], c.chroma[3], c.chroma[4]);
  EXPECT_GT(mean_var, 0);
  for (int k = 1; k <= 4; ++k) {
    EXPECT_LT(c.lum[k], 1.0);
    EXPECT_LT(c.chroma[k], 1.0);
  }
  // Measured: 0.0854 on this crop and grid (0.97 - 0.98 at levels 2 - 4, chroma ~0.99; 0.163
  // before the estimate took detail repeated in the partner image for texture, noise.cpp).
  // 1 - ceiling is the noise's SSIM loss: two-sided on level 1 (the shortest vectors, lowest ceiling).
  in_band(1 - c.lum[1], 0.09, "1 - luminance noise ceiling at level 1");
  // noise=auto caps the thresholds at the ceilings.
  auto m = encode(b, "mlvq:scheme=4:phi=8:theta=4:alpha=7:beta=7:noise=auto:ssim1=0.999:ssim4=0.9");
  ASSERT_TRUE(m.ok()) << m.status().message();
  EXPECT_NEAR(stat(*m.value(), "threshold.lum1"), std::max(c.lum[1], 0.999 - 0.2), 1e-9);
  EXPECT_NEAR(stat(*m.value(), "threshold.lum4"), std::min(0.9, c.lum[4]), 1e-9);
}

// The default (measured layout, noise-capped thresholds) on a 16 x 16 crop: no resampling error,
// the level-1 threshold set by the noise, and error / ratio / MSSIM (btfc's metric with each
// image's maximum as data range, as scripts/mssim.py) in measured bands.
// Measured (crop x, y = 16..31): level-1 threshold 0.8995 (the noise ceiling), rel_l2 0.380,
// MSSIM 0.540, 112.1 : 1 (before the partner-image noise estimate: 0.8758, 0.387, 0.525, 124.7 : 1;
// the full textile: docs/benchmarks.md).
constexpr double BOUND_NOISE = 0.11, BOUND_REL = 0.42, BOUND_SSIM = 0.52, BOUND_RATIO = 140;

TEST(MlvqTextile, DefaultOnACropHasMeasuredQualityRatioAndNoiseThreshold) {
  ASSERT_TRUE(have_data()) << "../shared/data/textile_lurex_utia64 is missing";
  const Btf b = crop(16, 16, 16);
  auto m = encode(b, "mlvq");
  ASSERT_TRUE(m.ok()) << m.status().message();
  Btf out;
  ASSERT_TRUE(m.value()->decode_all(out).ok());
  auto mt = compare_btf(b, out);
  ASSERT_TRUE(mt.ok());
  const Model& mm = *m.value();
  std::printf("rel_l2 %.4f mssim %.4f ratio %.2f lum1 threshold %.4f (ceiling %.4f) resample %.3g relaxed %g\n", mt->rel_l2, mt->mean_ssim,
              payload_ratio(mm), stat(mm, "threshold.lum1"), stat(mm, "noise_ceiling.lum1"), stat(mm, "resample_rel_rmse"),
              stat(mm, "relaxed"));
  EXPECT_EQ(stat(mm, "layout_measured"), 1);
  EXPECT_LE(stat(mm, "resample_rel_rmse"), 1e-5);
  EXPECT_EQ(stat(mm, "relaxed"), 0);
  // Level 1 (9 measured values) is where the noise binds; the levels above keep 0.95 / 0.93 / 0.9.
  EXPECT_LT(stat(mm, "threshold.lum1"), 0.9);
  EXPECT_EQ(stat(mm, "threshold.lum1"), stat(mm, "noise_ceiling.lum1"));
  EXPECT_EQ(stat(mm, "threshold.lum4"), 0.95);
  in_band(1 - stat(mm, "threshold.lum1"), BOUND_NOISE, "1 - level-1 threshold (noise ceiling)");
  in_band(mt->rel_l2, BOUND_REL, "relative L2 error");
  in_band(1 - mt->mean_ssim, BOUND_SSIM, "1 - MSSIM");
  in_band(payload_ratio(mm), BOUND_RATIO, "ratio vs float32");
}
