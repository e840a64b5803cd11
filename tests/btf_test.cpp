#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <vector>

#include "codecs/codec.h"
#include "core/btf.h"

using namespace btfc;

static BtfDesc small_desc(int w, int h, int nl, int nv) {
  BtfDesc d;
  d.width = w, d.height = h;
  for (int i = 0; i < nl; ++i) d.lights.dirs.push_back(dir_from_theta_phi(0.1 * i, 0.3 * i));
  for (int i = 0; i < nv; ++i) d.views.dirs.push_back(dir_from_theta_phi(0.2 * i, 0.5 * i));
  d.lights.name = d.views.name = "custom";
  return d;
}

TEST(DirectionSet, BuiltInSamplings) {
  DirectionSet a = DirectionSet::ubo2003(), b = DirectionSet::ubo2014();
  ASSERT_EQ(a.size(), 81u);
  ASSERT_EQ(b.size(), 151u);
  EXPECT_NEAR(a.dirs[0].z, 1.0f, 1e-7);
  // Light 1 of UBO2003 is theta 15, phi 0 (file 00081 tl015 pl000).
  double th, ph;
  dir_to_theta_phi(a.dirs[1], th, ph);
  EXPECT_NEAR(th * 180 / M_PI, 15.0, 1e-4);
  EXPECT_NEAR(ph, 0.0, 1e-6);
  dir_to_theta_phi(a.dirs[80], th, ph);  // last: theta 75, phi 345
  EXPECT_NEAR(th * 180 / M_PI, 75.0, 1e-4);
  EXPECT_NEAR(ph * 180 / M_PI, 345.0, 1e-3);
  dir_to_theta_phi(b.dirs[150], th, ph);  // UBO2014 last ring theta 75, 24 directions from phi 0
  EXPECT_NEAR(th * 180 / M_PI, 75.0, 1e-4);
  EXPECT_NEAR(ph * 180 / M_PI, 345.0, 1e-3);
  dir_to_theta_phi(b.dirs[7], th, ph);  // ring 2 (theta 23.5), offset 0
  EXPECT_NEAR(th * 180 / M_PI, 23.5, 1e-4);
  for (const auto& d : b.dirs) EXPECT_NEAR(d.x * d.x + d.y * d.y + d.z * d.z, 1.0f, 1e-6);
  DirectionSet c = a;
  c.name = "x";
  c.identify();
  EXPECT_EQ(c.name, "ubo2003");
  c.dirs[3].z = -c.dirs[3].z;
  c.identify();
  EXPECT_EQ(c.name, "custom");
  EXPECT_EQ(a.find(a.dirs[40]), 40);
  EXPECT_EQ(a.find(dir_from_theta_phi(0.9, 0.123)), -1);
}

TEST(Btf, LayoutImageAndMatrixViewsShareTheBuffer) {
  auto r = Btf::create(small_desc(5, 3, 4, 2));
  ASSERT_TRUE(r.ok());
  Btf& b = r.value();
  const BtfDesc& d = b.desc();
  EXPECT_EQ(d.abrdf_size(), 4u * 2 * 3);
  for (int y = 0; y < 3; ++y)
    for (int x = 0; x < 5; ++x)
      for (int v = 0; v < 2; ++v)
        for (int l = 0; l < 4; ++l)
          for (int c = 0; c < 3; ++c) b.at(x, y, l, v, c) = float(x + 10 * y + 100 * l + 1000 * v + 10000 * c);
  // Matrix view: column = texel x + W y, row = c + 3 (l + nL v), column-major with ld = rows.
  const size_t rows = d.abrdf_size();
  EXPECT_EQ(b.data()[(2 + 5 * 1) * rows + (1 + 3 * (3 + 4 * 1))], 2 + 10 + 300 + 1000 + 10000);
  // Image view of (light 2, view 1) is strided into the same buffer.
  ImageView iv = b.image(2, 1);
  EXPECT_EQ(iv.at(4, 2, 2), 4 + 20 + 200 + 1000 + 20000);
  EXPECT_EQ(iv.base - b.data(), ptrdiff_t(d.row(2, 1, 0)));
  // ABRDF view: contiguous per texel.
  EXPECT_EQ(b.abrdf(7)[d.row(3, 0, 1)], 2 + 10 + 300 + 10000);
}

TEST(Btf, ValidateAndLimits) {
  BtfDesc d = small_desc(0, 3, 1, 1);
  EXPECT_FALSE(Btf::create(d).ok());
  d = small_desc(2048, 2048, 151, 151);
  auto r = Btf::create(d, size_t(1) << 32);  // 3.4 TB: rejected before allocating
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("memory limit"), std::string::npos);
  d = small_desc(1 << 20, 1 << 20, 1 << 10, 1 << 10);
  EXPECT_NE(Btf::create(d).status().message().find("overflows"), std::string::npos);
  d = small_desc(2, 2, 1, 1);
  d.lights.dirs[0] = Vec3{0, 0, 2};
  EXPECT_FALSE(d.validate().ok());
}

TEST(Btf, NonFiniteIsAnErrorNamingThePosition) {
  auto b = Btf::create(small_desc(3, 2, 2, 2)).value();
  EXPECT_TRUE(b.check_finite("x").ok());
  b.at(1, 1, 1, 0, 2) = std::nanf("");
  Status s = b.check_finite("input.btfc");
  EXPECT_EQ(s.code(), StatusCode::corrupt_data);
  EXPECT_NE(s.message().find("input.btfc"), std::string::npos);
  EXPECT_NE(s.message().find("texel (1, 1), light 1, view 0, channel 2"), std::string::npos) << s.message();
  b.at(1, 1, 1, 0, 2) = INFINITY;
  EXPECT_FALSE(b.check_finite("x").ok());
}

TEST(DecodeRequest, ResolvesSubsetsAndRejectsBadOnes) {
  BtfDesc d = small_desc(8, 6, 5, 3);
  DecodeRequest q;
  q.x0 = 2, q.y0 = 1, q.width = 3, q.height = 4;
  q.lights = {4, 0};
  auto r = resolve_request(d, q);
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->desc.width, 3);
  EXPECT_EQ(r->desc.num_lights(), 2u);
  EXPECT_EQ(r->desc.num_views(), 3u);
  EXPECT_EQ(r->lights, (std::vector<int>{4, 0}));
  q.width = 7;
  EXPECT_FALSE(resolve_request(d, q).ok());
  q.width = 3;
  q.views = {3};
  EXPECT_NE(resolve_request(d, q).status().message().find("view index 3"), std::string::npos);
}

TEST(Btf, FitScaleExponentAndTheScaledCopy) {
  // Inside [2^-32, 2^32] nothing is scaled; outside, 2^k brings the peak into [1, 2).
  EXPECT_EQ(btfc::fit_scale_exponent(1.0f), 0);
  EXPECT_EQ(btfc::fit_scale_exponent(std::ldexp(1.0f, 32) * 0.999f), 0);
  EXPECT_EQ(btfc::fit_scale_exponent(std::ldexp(1.0f, -32)), 0);
  EXPECT_EQ(btfc::fit_scale_exponent(std::ldexp(1.0f, 32)), -32);
  EXPECT_EQ(btfc::fit_scale_exponent(std::ldexp(1.0f, -33)), 33);
  EXPECT_EQ(btfc::fit_scale_exponent(3e38f), -127);
  EXPECT_EQ(btfc::fit_scale_exponent(1e-40f), 133);  // subnormal: ilogb -133
  EXPECT_EQ(btfc::fit_scale_exponent(0.0f), 0);
  EXPECT_EQ(btfc::fit_scale_exponent(INFINITY), 0);
  EXPECT_EQ(btfc::fit_scale_exponent(NAN), 0);
  btfc::BtfDesc d;
  d.width = 3, d.height = 1;
  d.lights.dirs = {btfc::Vec3{0, 0, 1}}, d.views.dirs = {btfc::Vec3{0, 0, 1}};
  btfc::Btf b = btfc::Btf::create(d).value();
  const float v[9] = {1e-40f, -2e-39f, 0, 3e-38f, -1e-45f, 5e-41f, 1e-39f, 0, -7e-40f};
  std::copy(v, v + 9, b.data());
  EXPECT_EQ(btfc::max_abs(b.data(), b.size()), 3e-38f);
  const int k = btfc::fit_scale_exponent(btfc::max_abs(b.data(), b.size()));
  EXPECT_EQ(k, 125);
  auto up = btfc::scaled_copy(b, k);
  ASSERT_TRUE(up.ok());
  for (size_t i = 0; i < 9; ++i) EXPECT_EQ(up->data()[i], std::ldexp(v[i], k)) << i;  // exact, subnormals too
  auto back = btfc::scaled_copy(up.value(), -k);
  ASSERT_TRUE(back.ok());
  for (size_t i = 0; i < 9; ++i) EXPECT_EQ(back->data()[i], v[i]) << i;
  std::vector<float> big(100000, -2.0f);
  big[77777] = -3.4e38f;
  EXPECT_EQ(btfc::max_abs(big.data(), big.size()), 3.4e38f);
}

// find_non_finite: first NaN / Inf over many blocks (the parallel, vectorized path), none, and
// a value in the last partial block.
TEST(Btf, FindNonFiniteFindsTheFirstOne) {
  std::vector<float> v((size_t(1) << 16) * 40 + 7, 0.5f);
  EXPECT_EQ(btfc::find_non_finite(v.data(), v.size()), v.size());
  v[v.size() - 1] = -INFINITY;
  EXPECT_EQ(btfc::find_non_finite(v.data(), v.size()), v.size() - 1);
  v[(size_t(1) << 16) * 23 + 5] = NAN;
  v[(size_t(1) << 16) * 31] = INFINITY;
  EXPECT_EQ(btfc::find_non_finite(v.data(), v.size()), (size_t(1) << 16) * 23 + 5);
  v[3] = std::numeric_limits<float>::max();  // finite
  EXPECT_EQ(btfc::find_non_finite(v.data(), 100), size_t(100));
}
