// Truncated SVD for fmf; see svd.h for the contract and the choice of paths.
#include "core/svd.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <random>

namespace btfc {

using Eigen::Index;
using Eigen::MatrixXd;
using Eigen::MatrixXf;
using ConstMapF = Eigen::Map<const MatrixXf>;

double SvdResult::rel_error_estimate() const {
  if (total_energy <= 0) return 0;
  return std::sqrt(std::max(0.0, total_energy - kept_energy) / total_energy);
}

namespace {

constexpr double k_rel_sigma_floor = 1e-6;  // float data: smaller singular values are noise

// All eigenpairs, sorted by descending eigenvalue.
void sorted_eigen(const MatrixXd& G, Eigen::VectorXd& lambda, MatrixXd& vecs) { top_eigenpairs(G, G.rows(), lambda, vecs); }

double frobenius2(ConstMapF& B) {
  double total = 0;
  const Index n = B.cols();
#pragma omp parallel for reduction(+ : total) schedule(static)
  for (Index j = 0; j < n; ++j) total += B.col(j).cast<double>().squaredNorm();
  return total;
}

Result<SvdResult> exact_svd(ConstMapF& B, const SvdOptions& opt) {
  const Index m = B.rows(), n = B.cols();
  const bool rows_small = m <= n;
  const Index k = rows_small ? m : n;
  // Gram matrix in double. B B^T is accumulated over column blocks so no double copy of B
  // exists; B^T B is only chosen when n < m (few texels), where the copy is small.
  MatrixXd G = MatrixXd::Zero(k, k);
  const Index block = 4096;
  // One step per Gram block, one for the eigendecomposition, one for the projection.
  if (opt.progress) opt.progress->start("fmf exact SVD", uint64_t((n + block - 1) / block) + 2);
  if (rows_small) {
    for (Index j0 = 0; j0 < n; j0 += block) {
      const Index nb = std::min(block, n - j0);
      MatrixXd Bd = B.middleCols(j0, nb).cast<double>();
      G.selfadjointView<Eigen::Lower>().rankUpdate(Bd);
      if (opt.progress) opt.progress->advance();
    }
    G.triangularView<Eigen::StrictlyUpper>() = G.transpose();
  } else {
    MatrixXd Bd = B.cast<double>();
    G.noalias() = Bd.transpose() * Bd;
    if (opt.progress) opt.progress->advance((n + block - 1) / block);
  }

  Eigen::VectorXd lambda;
  MatrixXd E;
  sorted_eigen(G, lambda, E);
  if (opt.progress) opt.progress->advance();
  SvdResult r;
  r.method = "exact";
  r.requested_rank = opt.max_rank;
  r.total_energy = lambda.sum();  // trace(G) = ||B||_F^2, in double
  const int rank = choose_rank(lambda, r.total_energy, opt, r.data_rank_limit, r.target_reached);
  r.S = lambda.head(rank).cwiseSqrt();
  r.kept_energy = lambda.head(rank).sum();
  if (rows_small) {
    // U = top eigenvectors of B B^T; SxV = B^T U is the projection (no division by sigma).
    MatrixXd U = E.leftCols(rank);
    MatrixXd SxV = B.cast<double>().transpose() * U;
    r.U = U.cast<float>();
    r.SxV = SxV.cast<float>();
  } else {
    // V = top eigenvectors of B^T B; U = B V / sigma; SxV = V sigma. Kept sigma > floor > 0,
    // except for all-zero input, where U is left zero.
    MatrixXd V = E.leftCols(rank);
    MatrixXd U = B.cast<double>() * V;
    for (int c = 0; c < rank; ++c) U.col(c) *= r.S(c) > 0 ? 1.0 / r.S(c) : 0.0;
    r.U = U.cast<float>();
    r.SxV = (V * r.S.asDiagonal()).cast<float>();
  }
  if (opt.progress) opt.progress->finish();
  return r;
}

// Orthonormal basis of the columns of Y (thin Householder QR in double for stability).
MatrixXf orthonormalize(const MatrixXf& Y) {
  MatrixXd Yd = Y.cast<double>();
  Eigen::HouseholderQR<MatrixXd> qr(Yd);
  MatrixXd Q = qr.householderQ() * MatrixXd::Identity(Y.rows(), Y.cols());
  return Q.cast<float>();
}

Result<SvdResult> randomized_svd(ConstMapF& B, const SvdOptions& opt) {
  const Index m = B.rows(), n = B.cols();
  const Index l = std::min<Index>(std::min(m, n), Index(opt.max_rank) + opt.oversample);
  if (opt.progress) opt.progress->start("fmf randomized SVD", uint64_t(2 * opt.power_iters + 3));
  auto step = [&] { if (opt.progress) opt.progress->advance(); };

  // Gaussian test matrix from a seeded engine: Box-Muller on raw 64-bit draws so the numbers
  // do not depend on the standard library's distribution implementation.
  MatrixXf Omega(n, l);
  std::mt19937_64 rng(opt.seed);
  const double k_two_pi = 6.283185307179586;
  for (Index i = 0; i < Omega.size(); i += 2) {
    double u1 = (double(rng() >> 11) + 0.5) * (1.0 / 9007199254740992.0);
    double u2 = (double(rng() >> 11) + 0.5) * (1.0 / 9007199254740992.0);
    double rad = std::sqrt(-2.0 * std::log(u1));
    Omega.data()[i] = float(rad * std::cos(k_two_pi * u2));
    if (i + 1 < Omega.size()) Omega.data()[i + 1] = float(rad * std::sin(k_two_pi * u2));
  }
  SvdResult r;
  r.method = "randomized";
  r.requested_rank = opt.max_rank;
  r.total_energy = frobenius2(B);
  step();

  MatrixXf Y = B * Omega;  // m x l
  Omega.resize(0, 0);
  step();
  MatrixXf Q = orthonormalize(Y);
  MatrixXf Z;
  for (int it = 0; it < opt.power_iters; ++it) {
    Z.noalias() = B.transpose() * Q;  // n x l
    step();
    Z = orthonormalize(Z);
    Y.noalias() = B * Z;
    step();
    Q = orthonormalize(Y);
  }
  // W^T = B^T Q (n x l); the small SVD comes from the l x l Gram matrix of W^T, in double.
  MatrixXf Wt = B.transpose() * Q;
  step();
  MatrixXd G = (Wt.transpose() * Wt).cast<double>();
  Eigen::VectorXd lambda;
  MatrixXd E;
  sorted_eigen(G, lambda, E);
  const int rank = choose_rank(lambda, r.total_energy, opt, r.data_rank_limit, r.target_reached);
  r.S = lambda.head(rank).cwiseSqrt();
  r.kept_energy = lambda.head(rank).sum();
  MatrixXf Ek = E.leftCols(rank).cast<float>();
  r.U = Q * Ek;
  r.SxV = Wt * Ek;
  if (opt.progress) opt.progress->finish();
  return r;
}

}  // namespace

int choose_rank(const Eigen::VectorXd& lambda, double total, const SvdOptions& opt, int& data_rank, bool& reached) {
  const Index k = lambda.size();
  const double floor = lambda.size() ? lambda(0) * k_rel_sigma_floor * k_rel_sigma_floor : 0;
  data_rank = 0;
  while (data_rank < k && lambda(data_rank) > floor && lambda(data_rank) > 0) ++data_rank;
  int rank = std::min<int>(opt.max_rank, data_rank);
  reached = true;
  if (opt.target_rel_error > 0 && total > 0) {
    const double allowed = opt.target_rel_error * opt.target_rel_error * total;
    double kept = 0;
    int r = 0;
    while (r < rank && total - kept > allowed) kept += lambda(r++);
    reached = total - kept <= allowed * (1 + 1e-9);
    rank = r;
  }
  return std::max(rank, 1);
}

void top_eigenpairs(const MatrixXd& G, Index l, Eigen::VectorXd& lambda, MatrixXd& vecs) {
  Eigen::SelfAdjointEigenSolver<MatrixXd> es(G);
  const Index k = G.rows();
  lambda.resize(l);
  vecs.resize(k, l);
  for (Index i = 0; i < l; ++i) {  // Eigen returns ascending order
    lambda(i) = std::max(0.0, es.eigenvalues()(k - 1 - i));
    vecs.col(i) = es.eigenvectors().col(k - 1 - i);
  }
}

Result<SvdResult> truncated_svd(const float* B, size_t m, size_t n, const SvdOptions& opt) {
  if (m == 0 || n == 0) return invalid_argument("SVD of an empty matrix");
  if (opt.max_rank < 1) return invalid_argument("SVD rank must be >= 1");
  ConstMapF map(B, Index(m), Index(n));
  SvdMethod method = opt.method;
  if (method == SvdMethod::automatic) method = std::min(m, n) <= 1024 ? SvdMethod::exact : SvdMethod::randomized;
  // The randomized sketch cannot exceed the small side; then the exact path is both exact and cheap.
  if (method == SvdMethod::randomized && size_t(opt.max_rank) + size_t(opt.oversample) >= std::min(m, n))
    method = SvdMethod::exact;
  return method == SvdMethod::exact ? exact_svd(map, opt) : randomized_svd(map, opt);
}

}  // namespace btfc
