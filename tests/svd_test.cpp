// core/svd.h: the exact path's LAPACK eigensolver against Eigen's (the reference), the automatic
// choice of path, and the reuse of exact decompositions during a byte-budget search.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <random>

#include "core/svd.h"

namespace btfc {
namespace {

// m x n column-major: rank-r structure with geometrically falling singular values plus noise.
std::vector<float> test_matrix(size_t m, size_t n, int r, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<float> g(0.f, 1.f);
  Eigen::MatrixXf U(m, r), V(n, r);
  for (Eigen::Index i = 0; i < U.size(); ++i) U.data()[i] = g(rng);
  for (Eigen::Index i = 0; i < V.size(); ++i) V.data()[i] = g(rng);
  for (int c = 0; c < r; ++c) U.col(c) *= std::pow(0.8f, float(c));
  Eigen::MatrixXf B = U * V.transpose();
  for (Eigen::Index i = 0; i < B.size(); ++i) B.data()[i] += 1e-3f * g(rng);
  return std::vector<float>(B.data(), B.data() + B.size());
}

TEST(Svd, LargeGramEigenpairsEqualEigensSolver) {
  // 1100 > 1024: top_eigenpairs asks LAPACK (dsyevd) when built with OpenBLAS; Eigen's solver is
  // the reference. Eigenvalues agree to double round-off relative to the largest; eigenvectors
  // span the same lines (|cos| = 1) where the eigenvalues are well separated.
  const Eigen::Index k = 1100;
  const std::vector<float> b = test_matrix(k, 1300, 40, 3);
  Eigen::Map<const Eigen::MatrixXf> B(b.data(), k, 1300);
  const Eigen::MatrixXd G = B.cast<double>() * B.cast<double>().transpose();
  Eigen::VectorXd lambda;
  Eigen::MatrixXd vecs;
  top_eigenpairs(G, 30, lambda, vecs);
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> ref(G);
  double max_rel = 0, min_cos = 1;
  for (int i = 0; i < 30; ++i) {
    max_rel = std::max(max_rel, std::abs(lambda(i) - ref.eigenvalues()(k - 1 - i)) / ref.eigenvalues()(k - 1));
    min_cos = std::min(min_cos, std::abs(vecs.col(i).dot(ref.eigenvectors().col(k - 1 - i))));
  }
  std::printf("max relative eigenvalue difference %.3g, min |cos| %.12f\n", max_rel, min_cos);
  EXPECT_LT(max_rel, 1e-12);
  EXPECT_GT(min_cos, 1 - 1e-9);
  for (int i = 1; i < 30; ++i) EXPECT_GE(lambda(i - 1), lambda(i));
}

TEST(Svd, AutomaticPathIsExactForLargeRanksOfAModerateSide) {
  const size_t m = 1300, n = 1100;  // small side 1100: randomized at rank 32, exact from rank 122
  const std::vector<float> b = test_matrix(m, n, 60, 4);
  SvdOptions o;
  o.max_rank = 32;
  auto low = truncated_svd(b.data(), m, n, o);
  ASSERT_TRUE(low.ok()) << low.status().message();
  EXPECT_EQ(low->method, "randomized");
  o.max_rank = 200;  // (200 + 16) x 8 >= 1100
  auto high = truncated_svd(b.data(), m, n, o);
  ASSERT_TRUE(high.ok()) << high.status().message();
  EXPECT_EQ(high->method, "exact");
  // Exact: the kept energy is the Eckart-Young optimum, the sum of the top 200 eigenvalues.
  EXPECT_NEAR(high->rel_error_estimate(), std::sqrt(std::max(0.0, high->total_energy - high->kept_energy) / high->total_energy), 1e-12);
  EXPECT_LE(high->rel_error_estimate(), low->rel_error_estimate());
}

TEST(Svd, ReuseServesAnExactSvdAgainAtAnotherRankWithTheSameResult) {
  const size_t m = 300, n = 200;
  const std::vector<float> b = test_matrix(m, n, 20, 5);
  SvdOptions o;
  o.method = SvdMethod::exact;
  o.max_rank = 12;
  auto plain12 = truncated_svd(b.data(), m, n, o);
  ASSERT_TRUE(plain12.ok());
  const size_t before = ExactSvdReuse::reuses();
  {
    const ExactSvdReuse reuse;
    o.max_rank = 20;
    ASSERT_TRUE(truncated_svd(b.data(), m, n, o).ok());
    o.max_rank = 12;
    auto again = truncated_svd(b.data(), m, n, o);
    ASSERT_TRUE(again.ok());
    EXPECT_EQ(ExactSvdReuse::reuses(), before + 1);
    EXPECT_EQ(again->U, plain12->U);  // bit for bit: the same decomposition, truncated
    EXPECT_EQ(again->SxV, plain12->SxV);
    // Other content (one value changed): not reused.
    std::vector<float> c = b;
    c[17] += 1.0f;
    ASSERT_TRUE(truncated_svd(c.data(), m, n, o).ok());
    EXPECT_EQ(ExactSvdReuse::reuses(), before + 1);
  }
  // Outside a scope nothing is kept.
  ASSERT_TRUE(truncated_svd(b.data(), m, n, o).ok());
  EXPECT_EQ(ExactSvdReuse::reuses(), before + 1);
}

}  // namespace
}  // namespace btfc
