// Synthetic BTF generator: determinism, value sanity, degenerate shapes, shadowing, scale.
#include "core/synth.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#ifdef _OPENMP
#include <omp.h>
#endif

namespace btfc {
namespace {
constexpr double k_pi = 3.14159265358979323846;

SynthOptions small(int w = 16, int h = 12) {
  SynthOptions o;
  o.width = w, o.height = h;
  return o;
}

bool same_bytes(const Btf& a, const Btf& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0;
}

TEST(Synth, IsDeterministic) {
  auto a = synthesize_btf(small()), b = synthesize_btf(small());
  ASSERT_TRUE(a.ok()) << a.status().message();
  ASSERT_TRUE(b.ok());
  EXPECT_TRUE(same_bytes(a.value(), b.value()));
  EXPECT_EQ(a->desc().summary(), b->desc().summary());
}

TEST(Synth, ThreadCountDoesNotChangeBits) {
#ifndef _OPENMP
  GTEST_SKIP() << "built without OpenMP";
#else
  const int saved = omp_get_max_threads();
  omp_set_num_threads(1);
  auto a = synthesize_btf(small(9, 7));
  omp_set_num_threads(3);
  auto b = synthesize_btf(small(9, 7));
  omp_set_num_threads(saved);
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_TRUE(same_bytes(a.value(), b.value()));
#endif
}

TEST(Synth, DifferentSeedsDiffer) {
  SynthOptions o = small();
  auto a = synthesize_btf(o);
  o.seed = 2;
  auto b = synthesize_btf(o);
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_FALSE(same_bytes(a.value(), b.value()));
}

TEST(Synth, ValuesFiniteNonNegativeAndVaried) {
  auto r = synthesize_btf(small());
  ASSERT_TRUE(r.ok());
  const BtfDesc& d = r->desc();
  EXPECT_EQ(d.width, 16);
  EXPECT_EQ(d.height, 12);
  EXPECT_EQ(d.channels, 3);
  EXPECT_EQ(d.lights.name, "ubo2003");
  EXPECT_EQ(d.views.name, "ubo2003");
  EXPECT_TRUE(r->check_finite("synth").ok());
  double sum = 0, hi = 0;
  for (size_t i = 0; i < r->size(); ++i) {
    ASSERT_GE(r->data()[i], 0.0f) << i;
    sum += r->data()[i], hi = std::max(hi, double(r->data()[i]));
  }
  const double mean = sum / double(r->size());
  EXPECT_GT(mean, 0.02);  // "roughly within [0, 1]"
  EXPECT_LT(mean, 0.5);
  EXPECT_LT(hi, 3.0);
  // Spatial variation: the frontal image is not constant.
  const ImageView img = r->image(0, 0);
  EXPECT_NE(img.at(0, 0, 0), img.at(5, 7, 0));
}

TEST(Synth, HandlesOneTexel) {
  auto r = synthesize_btf(small(1, 1));
  ASSERT_TRUE(r.ok()) << r.status().message();
  EXPECT_EQ(r->size(), size_t(81 * 81 * 3));
  EXPECT_TRUE(r->check_finite("synth").ok());
  EXPECT_GT(r->at(0, 0, 0, 0, 0), 0.0f);
}

TEST(Synth, HandlesSingleDirectionSets) {
  SynthOptions o = small(8, 8);
  o.lights = DirectionSet::single(dir_from_theta_phi(60 * k_pi / 180, 0.3));
  o.views = DirectionSet::single({0, 0, 1});
  auto r = synthesize_btf(o);
  ASSERT_TRUE(r.ok()) << r.status().message();
  EXPECT_EQ(r->size(), size_t(8 * 8 * 3));
  EXPECT_TRUE(r->check_finite("synth").ok());
  // Same texels, same parameters: equal to the matching entries of a full-set synthesis
  // (directions only select rows; the material does not depend on the sets).
  SynthOptions full = o;
  full.lights = DirectionSet::ubo2003();
  full.lights.dirs[5] = o.lights.dirs[0];
  auto f = synthesize_btf(full);
  ASSERT_TRUE(f.ok());
  for (int y = 0; y < 8; ++y)
    for (int x = 0; x < 8; ++x) EXPECT_EQ(r->at(x, y, 0, 0, 1), f->at(x, y, 5, 0, 1));
}

TEST(Synth, BelowHorizonIsZero) {
  SynthOptions o = small(4, 4);
  o.lights.dirs = {dir_from_theta_phi(0, 0), dir_from_theta_phi(100 * k_pi / 180, 0)};
  o.lights.name = "custom";
  auto r = synthesize_btf(o);
  ASSERT_TRUE(r.ok());
  EXPECT_GT(r->at(1, 1, 0, 0, 0), 0.0f);
  EXPECT_EQ(r->at(1, 1, 1, 0, 0), 0.0f);
}

TEST(Synth, BumpAndShadowingMatterAtGrazingLight) {
  SynthOptions o = small(32, 32);
  o.lights = DirectionSet::single(dir_from_theta_phi(75 * k_pi / 180, 0.4));
  o.views = DirectionSet::single({0, 0, 1});
  o.bump = 0.0f;
  auto flat = synthesize_btf(o);
  o.bump = 1.0f;
  auto bumpy = synthesize_btf(o);
  o.bump = 3.0f;
  auto rough = synthesize_btf(o);
  ASSERT_TRUE(flat.ok() && bumpy.ok() && rough.ok());
  EXPECT_FALSE(same_bytes(flat.value(), bumpy.value()));
  // The flat material is unshadowed; with relief, a part of the texels is darkened by more than
  // the specular/albedo variation can explain (shadow factor down to 0.15).
  auto shadowed_fraction = [&](const Btf& b) {
    int n = 0;
    for (int y = 0; y < 32; ++y)
      for (int x = 0; x < 32; ++x) n += b.at(x, y, 0, 0, 1) < 0.5f * flat->at(x, y, 0, 0, 1);
    return n / 1024.0;
  };
  EXPECT_EQ(shadowed_fraction(flat.value()), 0.0);
  const double fb = shadowed_fraction(bumpy.value()), fr = shadowed_fraction(rough.value());
  EXPECT_GT(fb, 0.02);
  EXPECT_GT(fr, fb);  // deeper relief, more shadow
  EXPECT_LT(fr, 0.95);
}

TEST(Synth, ScaleMultiplies) {
  SynthOptions o = small(6, 5);
  auto a = synthesize_btf(o);
  o.scale = 2.0f;
  auto b = synthesize_btf(o);
  o.scale = 1e6f;
  auto c = synthesize_btf(o);
  ASSERT_TRUE(a.ok() && b.ok() && c.ok());
  EXPECT_FALSE(a->desc().hdr);
  EXPECT_TRUE(c->desc().hdr);
  for (size_t i = 0; i < a->size(); ++i) {
    ASSERT_EQ(b->data()[i], 2.0f * a->data()[i]) << i;
    ASSERT_NEAR(c->data()[i], 1e6 * a->data()[i], 1e-6 * 1e6 * a->data()[i] + 1e-3) << i;
  }
}

// Measurement noise: each value times max(0, 1 + noise g), independent per value: the relative
// deviation from the clean values has standard deviation ~noise and mean ~0, and does not repeat
// between two images of one texel (that is what tells it from albedo texture).
TEST(Synth, NoiseIsMultiplicativeIndependentAndOfTheGivenSize) {
  SynthOptions o = small(8, 8);
  auto clean = synthesize_btf(o);
  o.noise = 0.1f;
  auto noisy = synthesize_btf(o), again = synthesize_btf(o);
  ASSERT_TRUE(clean.ok() && noisy.ok() && again.ok());
  double s = 0, s2 = 0, cross = 0;
  size_t n = 0;
  for (size_t i = 0; i + 3 < clean->size(); ++i) {
    ASSERT_EQ(noisy->data()[i], again->data()[i]) << "deterministic";
    ASSERT_GE(noisy->data()[i], 0.0f);
    if (clean->data()[i] <= 0 || clean->data()[i + 3] <= 0) continue;
    const double r = noisy->data()[i] / clean->data()[i] - 1, r3 = noisy->data()[i + 3] / clean->data()[i + 3] - 1;
    s += r, s2 += r * r, cross += r * r3, ++n;  // i + 3: the same channel of the next light
  }
  ASSERT_GT(n, 10000u);
  const double mean = s / double(n), sd = std::sqrt(s2 / double(n) - mean * mean);
  EXPECT_NEAR(sd, 0.1, 0.005);
  EXPECT_NEAR(mean, 0.0, 0.005);
  EXPECT_NEAR(cross / double(n) / (sd * sd), 0.0, 0.05);  // correlation between images
  o.noise = -1;
  EXPECT_EQ(synthesize_btf(o).status().code(), StatusCode::invalid_argument);
}

TEST(Synth, RejectsBadOptions) {
  SynthOptions o = small();
  o.bump = -1;
  EXPECT_EQ(synthesize_btf(o).status().code(), StatusCode::invalid_argument);
  o = small();
  o.scale = std::nanf("");
  EXPECT_EQ(synthesize_btf(o).status().code(), StatusCode::invalid_argument);
  o = small(0, 4);
  EXPECT_FALSE(synthesize_btf(o).ok());
  o = small();
  o.views.dirs.clear();
  EXPECT_FALSE(synthesize_btf(o).ok());
}

}  // namespace
}  // namespace btfc
