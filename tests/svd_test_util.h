// Matrices for the SVD tests (svd_test.cpp, svd_reuse_test.cpp: a fast and a slow spectral decay;
// svd_test.cpp: the in-core sparse start and ooc_test.cpp: the streamed Krylov SVD at the
// extremes) and the checks they run against the exact SVD.
#pragma once
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "core/svd.h"

namespace btfc::test {

// m x n column-major: rank-r structure with geometrically falling singular values plus noise.
inline std::vector<float> test_matrix(size_t m, size_t n, int r, uint64_t seed) {
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

// A slowly decaying spectrum, where power iterations need many passes: sigma_i = 1 / (1 + i)
// over the whole small side, with random singular vectors. Returns B and its exact singular values.
inline std::vector<float> slow_decay_matrix(size_t m, size_t n, uint64_t seed, Eigen::VectorXd& sigma) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> g(0.0, 1.0);
  const Eigen::Index k = Eigen::Index(std::min(m, n));
  Eigen::MatrixXd A(m, k), C(n, k);
  for (Eigen::Index i = 0; i < A.size(); ++i) A.data()[i] = g(rng);
  for (Eigen::Index i = 0; i < C.size(); ++i) C.data()[i] = g(rng);
  const Eigen::MatrixXd U = Eigen::HouseholderQR<Eigen::MatrixXd>(A).householderQ() * Eigen::MatrixXd::Identity(Eigen::Index(m), k);
  const Eigen::MatrixXd V = Eigen::HouseholderQR<Eigen::MatrixXd>(C).householderQ() * Eigen::MatrixXd::Identity(Eigen::Index(n), k);
  sigma.resize(k);
  for (Eigen::Index i = 0; i < k; ++i) sigma(i) = 1.0 / (1.0 + double(i));
  const Eigen::MatrixXf B = (U * sigma.asDiagonal() * V.transpose()).cast<float>();
  return std::vector<float>(B.data(), B.data() + B.size());
}

struct NamedMatrix {
  const char* name;
  std::vector<float> b;  // m x n, column-major
};

// zeros, a constant, rank 2 (Gaussian factors) and HDR rows spanning 1e-6 .. 1e6 (positive,
// with texture between columns), each m x n column-major.
inline std::vector<NamedMatrix> extreme_matrices(size_t m, size_t n, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<float> g(0.f, 1.f);
  std::vector<NamedMatrix> cases;
  cases.push_back({"zeros", std::vector<float>(m * n, 0.f)});
  cases.push_back({"constant", std::vector<float>(m * n, 3.5f)});
  Eigen::MatrixXf U(m, 2), V(n, 2);
  for (Eigen::Index i = 0; i < U.size(); ++i) U.data()[i] = g(rng);
  for (Eigen::Index i = 0; i < V.size(); ++i) V.data()[i] = g(rng);
  const Eigen::MatrixXf R2 = U * V.transpose();
  cases.push_back({"rank 2", std::vector<float>(R2.data(), R2.data() + R2.size())});
  std::vector<float> hdr(m * n);
  for (size_t j = 0; j < n; ++j)
    for (size_t i = 0; i < m; ++i)
      hdr[j * m + i] = (1.f + std::abs(g(rng)) + float(j % 7) * float(i % 5)) * std::pow(10.f, -6.f + 12.f * float(i) / float(m - 1));
  cases.push_back({"HDR 1e-6..1e6", std::move(hdr)});
  return cases;
}

// ||B - U SxV^T||_F / ||B||_F, in double.
inline double actual_rel_error(const std::vector<float>& b, size_t m, size_t n, const SvdResult& r) {
  Eigen::Map<const Eigen::MatrixXf> B(b.data(), Eigen::Index(m), Eigen::Index(n));
  const Eigen::MatrixXd D = B.cast<double>() - r.U.cast<double>() * r.SxV.cast<double>().transpose();
  return std::sqrt(D.squaredNorm() / B.cast<double>().squaredNorm());
}

// `r` against the exact SVD of the same matrix: finite factors, the same numerical rank, zeros
// give zeros, the error within 1 % of the optimum (exact fits, the constant and rank 2, reach
// float round-off: + 1e-5), and the data's singular values (a direction counted twice would
// inflate them). `what` names the case in failures.
inline void expect_like_exact(const NamedMatrix& c, size_t m, size_t n, const SvdResult& r, const SvdResult& exact, const std::string& what) {
  EXPECT_TRUE(r.U.allFinite() && r.SxV.allFinite()) << what;
  ASSERT_EQ(r.S.size(), exact.S.size()) << what;
  if (std::string(c.name) == "zeros") {
    EXPECT_EQ(r.SxV.cwiseAbs().maxCoeff(), 0.f) << what;
    return;
  }
  const double e = actual_rel_error(c.b, m, n, r), best = actual_rel_error(c.b, m, n, exact);
  EXPECT_LE(e, 1.01 * best + 1e-5) << what << ": " << e << " vs exact " << best;
  for (Eigen::Index i = 0; i < r.S.size(); ++i) EXPECT_NEAR(r.S(i), exact.S(i), 1e-3 * exact.S(0)) << what << " " << i;
}

}  // namespace btfc::test
