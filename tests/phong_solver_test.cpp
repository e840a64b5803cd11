// lpyr's Phong fit without Ceres (codecs/lpyr/phong_fit.cpp): the projected Levenberg-Marquardt
// that runs when btfc is built without Ceres recovers known parameters and reaches the same
// minimum as Ceres's LM (when the build has Ceres) on noisy and HDR data.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "codecs/lpyr/lpyr_internal.h"

namespace btfc {
namespace {

double sq_residual(const lpyr::PhongFit& f, const DirectionSet& L, const DirectionSet& V, const std::vector<double>& mu) {
  double e = 0;
  for (size_t r = 0; r < mu.size(); ++r) {
    const double d = lpyr::phong_eval(f.p, L.dirs[r % L.size()], V.dirs[r / L.size()]) - mu[r];
    e += d * d;
  }
  return e;
}

TEST(PhongSolver, ProjectedLmRecoversKnownParameters) {
  const DirectionSet L = DirectionSet::ubo2003(), V = DirectionSet::ubo2003();
  const lpyr::Phong truth{0.02f, 0.4f, 0.8f, 60.0f};
  std::vector<double> mu(L.size() * V.size());
  for (size_t r = 0; r < mu.size(); ++r) mu[r] = 1e3 * lpyr::phong_eval(truth, L.dirs[r % L.size()], V.dirs[r / L.size()]);
  const lpyr::PhongFit f = lpyr::fit_phong(L, V, mu.data(), lpyr::PhongSolver::projected);
  EXPECT_EQ(f.method, "lm-projected");
  EXPECT_NEAR(f.p.ka / 1e3, 0.02, 1e-3);
  EXPECT_NEAR(f.p.kd / 1e3, 0.4, 1e-3);
  EXPECT_NEAR(f.p.ks / 1e3, 0.8, 2e-3);
  EXPECT_NEAR(f.p.alpha, 60.0, 0.2);
  EXPECT_LT(f.rel_residual, 1e-5);
}

TEST(PhongSolver, ProjectedLmMatchesCeresOnNoisyData) {
  if (!lpyr::have_ceres()) GTEST_SKIP() << "built without Ceres: only the projected LM exists";
  const DirectionSet L = DirectionSet::ubo2003(), V = DirectionSet::ubo2003();
  std::mt19937 rng(7);
  std::normal_distribution<double> noise(0, 0.05);
  std::lognormal_distribution<double> hdr(0, 3);
  const lpyr::Phong truth{0.1f, 0.5f, 2.0f, 15.0f};
  for (int trial = 0; trial < 3; ++trial) {
    std::vector<double> mu(L.size() * V.size());
    for (size_t r = 0; r < mu.size(); ++r) {
      const double p = lpyr::phong_eval(truth, L.dirs[r % L.size()], V.dirs[r / L.size()]);
      mu[r] = trial == 2 ? hdr(rng) : p * (1 + noise(rng)) * (trial == 1 ? 1e5 : 1);
    }
    const lpyr::PhongFit c = lpyr::fit_phong(L, V, mu.data(), lpyr::PhongSolver::ceres);
    const lpyr::PhongFit p = lpyr::fit_phong(L, V, mu.data(), lpyr::PhongSolver::projected);
    EXPECT_EQ(c.method, "lm");
    EXPECT_EQ(p.method, "lm-projected");
    const double ec = sq_residual(c, L, V, mu), ep = sq_residual(p, L, V, mu);
    // The same minimum: within 0.1 % of the squared residual (either may be the lower).
    EXPECT_LE(std::abs(ep - ec), 1e-3 * ec) << "trial " << trial << ": ceres " << ec << ", projected " << ep;
  }
}

}  // namespace
}  // namespace btfc
