// Model::relight (codecs/relight.cpp): every codec relights by direct quadrature over the
// measured lights; lpca's override (seed 002's precomputed radiance transfer) must give the same
// sum, since projecting the eigen-BRDFs on SH with the same quadrature weights and dotting with
// the environment's coefficients is that sum reordered (exact for environments of at most the
// model's SH order). Two different computations agreeing is the check.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "codecs/codec.h"
#include "core/sh.h"
#include "core/synth.h"
#include "tests/codec_test_util.h"

namespace btfc {
namespace {

using test::encode_spec;

EnvironmentSH smooth_env(int order) {
  EnvironmentSH env;
  env.order = order;
  for (int c = 0; c < 3; ++c) {
    auto p = sh::project_function(
        order, [c](double x, double y, double z) { return 0.4 + 0.1 * c + 0.3 * z + (0.8 - 0.2 * c) * std::exp(2.5 * (0.5 * x + 0.2 * y + 0.84 * z - 1)); },
        64);
    env.coeffs.insert(env.coeffs.end(), p.begin(), p.end());
  }
  return env;
}

Btf synth(int w, int h, float scale = 1) {
  SynthOptions o;
  o.width = w, o.height = h, o.seed = 5, o.scale = scale;
  return std::move(synthesize_btf(o).value());
}

double max_abs(const std::vector<float>& v) {
  double m = 0;
  for (float x : v) m = std::max(m, double(std::abs(x)));
  return m;
}

TEST(Relight, LpcaPrtEqualsTheQuadratureOfItsOwnValues) {
  const Btf b = synth(6, 5);
  auto m = encode_spec(b, "lpca:clusters=2:components=3:precision=float");
  ASSERT_TRUE(m);
  for (int order : {1, 3, 5}) {  // <= the model's sh_order (5): the two sums are the same sum
    const EnvironmentSH env = smooth_env(order);
    for (const Vec3& v : {dir_from_theta_phi(0.0, 0.0), dir_from_theta_phi(0.6, 1.1), dir_from_theta_phi(1.1, 4.0)}) {
      auto prt = m->relight(env, v);
      auto quad = m->Model::relight(env, v);
      ASSERT_TRUE(prt.ok()) << prt.status().message();
      ASSERT_TRUE(quad.ok()) << quad.status().message();
      ASSERT_EQ(prt->size(), size_t(6 * 5 * 3));
      ASSERT_EQ(prt->size(), quad->size());
      const double mx = max_abs(*quad);
      ASSERT_GT(mx, 0);
      double err = 0;
      for (size_t i = 0; i < prt->size(); ++i) err = std::max(err, double(std::abs((*prt)[i] - (*quad)[i])));
      // float eigen_sh coefficients and float sums: a few 1e-6 of the peak
      EXPECT_LE(err, 2e-5 * mx) << "order " << order;
    }
  }
}

TEST(Relight, EveryCodecRelightsCloseToTheData) {
  // Reference: the same quadrature over the uncompressed values (a raw "model" is what the data
  // is: relit through an fmf model of full rank, float storage). Each codec's relit image is
  // within its compression error of it.
  const Btf b = synth(8, 8, 3.0f);
  const EnvironmentSH env = smooth_env(4);
  const Vec3 v = dir_from_theta_phi(0.5, 2.0);
  auto exact = encode_spec(b, "fmf:rank=4096:precision=float:svd=exact");
  ASSERT_TRUE(exact);
  auto ref = exact->relight(env, v);
  ASSERT_TRUE(ref.ok()) << ref.status().message();
  const double peak = max_abs(*ref);
  ASSERT_GT(peak, 0);
  for (const char* spec : {"fmf:rank=8", "lpyr", "lpca:clusters=2:components=4", "mlvq"}) {
    auto m = encode_spec(b, spec);
    ASSERT_TRUE(m) << spec;
    auto r = m->relight(env, v);
    ASSERT_TRUE(r.ok()) << spec << ": " << r.status().message();
    double e2 = 0, r2 = 0;
    for (size_t i = 0; i < r->size(); ++i) e2 += std::pow((*r)[i] - (*ref)[i], 2), r2 += std::pow((*ref)[i], 2);
    Btf dec;
    ASSERT_TRUE(m->decode_all(dec).ok());
    double d2 = 0, b2 = 0;
    for (size_t i = 0; i < b.size(); ++i) d2 += std::pow(double(dec.data()[i]) - b.data()[i], 2), b2 += std::pow(double(b.data()[i]), 2);
    const double relit = std::sqrt(e2 / r2), decoded = std::sqrt(d2 / b2);
    std::printf("[relight] %-32s relit rel. L2 %.4f, decoded rel. L2 %.4f\n", spec, relit, decoded);
    // Relighting is a positive weighted sum over the 81 lights of the decoded values: the
    // codec's errors average out (measured here: about a quarter of the decode's relative
    // error for every codec), so it must not exceed the decode's relative error.
    EXPECT_LE(relit, decoded + 1e-5) << spec;
  }
}

TEST(Relight, ErrorsNameTheProblem) {
  auto m = encode_spec(synth(4, 4), "fmf:rank=4");
  ASSERT_TRUE(m);
  auto below = m->relight(smooth_env(2), Vec3{0.f, 0.6f, -0.8f});
  ASSERT_FALSE(below.ok());
  EXPECT_NE(below.status().message().find("horizon"), std::string::npos);
  EnvironmentSH bad;
  bad.order = 3;
  auto empty = m->relight(bad, Vec3{0, 0, 1});
  ASSERT_FALSE(empty.ok());
  EXPECT_NE(empty.status().message().find("coefficients"), std::string::npos);
}

}  // namespace
}  // namespace btfc
