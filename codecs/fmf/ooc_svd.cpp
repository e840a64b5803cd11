// Streaming randomized SVD; see ooc_svd.h for the algorithm and the contracts.
#include "codecs/fmf/ooc_svd.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <random>

#include "codecs/fmf/ooc_pass.h"
#include "core/thin_product.h"

namespace btfc::fmf {
namespace {

using Eigen::Index;
using Eigen::MatrixXd;
using Eigen::MatrixXf;

// Orthonormal basis of Y's columns (thin Householder QR in double, as the in-core path).
MatrixXf orthonormalize(const MatrixXd& Y) {
  Eigen::HouseholderQR<MatrixXd> qr(Y);
  MatrixXd Q = qr.householderQ() * MatrixXd::Identity(Y.rows(), Y.cols());
  return Q.cast<float>();
}

// Omega's rows for texels [first, first + count): Gaussian, Box-Muller on raw 64-bit draws (as
// svd.cpp) from an engine seeded by (seed, first), so any process can make any chunk's rows.
void gaussian_rows(uint64_t seed, size_t first, size_t count, Index l, MatrixXf& out) {
  std::seed_seq seq{uint32_t(seed), uint32_t(seed >> 32), uint32_t(first), uint32_t(uint64_t(first) >> 32)};
  std::mt19937_64 rng(seq);
  out.resize(Index(count), l);
  const double k_two_pi = 6.283185307179586;
  for (Index i = 0; i < out.size(); i += 2) {
    const double u1 = (double(rng() >> 11) + 0.5) * (1.0 / 9007199254740992.0);
    const double u2 = (double(rng() >> 11) + 0.5) * (1.0 / 9007199254740992.0);
    const double rad = std::sqrt(-2.0 * std::log(u1));
    out.data()[i] = float(rad * std::cos(k_two_pi * u2));
    if (i + 1 < out.size()) out.data()[i + 1] = float(rad * std::sin(k_two_pi * u2));
  }
}

}  // namespace

Result<SvdResult> streaming_svd(const ChunkSource& src, const std::vector<size_t>& chunks, const SvdOptions& opt, Collective& coll,
                                StreamStats* stats_out) {
  const size_t m = src.rows(), n = src.texels();
  if (m == 0 || n == 0) return invalid_argument("SVD of an empty matrix");
  if (opt.max_rank < 1) return invalid_argument("SVD rank must be >= 1");
  const Index l = Index(std::min<size_t>(std::min(m, n), size_t(opt.max_rank) + size_t(opt.oversample)));
  const int total_passes = opt.power_iters + 2;
  PassRunner run(src, chunks, coll, opt.progress, "fmf out-of-core SVD", total_passes);
  std::vector<double>& buf = run.sums();

  // Pass 0: sketch and energy.
  MatrixXd Y = MatrixXd::Zero(Index(m), l);
  double energy = 0;
  {
    MatrixXf Om, Yf;
    auto sketch = [&](size_t c, const float* Bp, size_t k) {
      Eigen::Map<const MatrixXf> B(Bp, Index(m), Index(k));
      // Column sums in float (short), accumulated in double; serial: see ooc_pass.cpp.
      for (Index j = 0; j < Index(k); ++j) energy += double(B.col(j).squaredNorm());
      gaussian_rows(opt.seed, src.chunk_first(c), k, l, Om);
      thin_product(Bp, m, k, Om, Yf);
      Y += Yf.cast<double>();
    };
    BTFC_RETURN_IF_ERROR(run.pass(m * size_t(l) + 1, sketch, [&](double* d) {
      std::copy(Y.data(), Y.data() + Y.size(), d);
      d[Y.size()] = energy;
    }));
    Y = Eigen::Map<MatrixXd>(buf.data(), Index(m), l);
    energy = buf[m * size_t(l)];
  }
  BTFC_RETURN_IF_ERROR(src.finish_first_pass(coll));
  // Passes 1..q: Y = B B^T Q.
  MatrixXf Q = orthonormalize(Y);
  for (int it = 0; it < opt.power_iters; ++it) {
    Y.setZero();
    MatrixXf Z, Yf;
    auto power = [&](size_t, const float* Bp, size_t k) {
      transposed_product(Bp, m, k, Q, Z);
      thin_product(Bp, m, k, Z, Yf);
      Y += Yf.cast<double>();
    };
    BTFC_RETURN_IF_ERROR(run.pass(m * size_t(l), power, [&](double* d) { std::copy(Y.data(), Y.data() + Y.size(), d); }));
    Y = Eigen::Map<MatrixXd>(buf.data(), Index(m), l);
    Q = orthonormalize(Y);
  }
  Y.resize(0, 0);
  // Last pass: W^T = B^T Q for the owned texels, and its Gram matrix.
  std::vector<std::pair<size_t, MatrixXf>> wt;  // (chunk, rows of W^T)
  MatrixXd G = MatrixXd::Zero(l, l);
  auto project = [&](size_t c, const float* Bp, size_t k) {
    MatrixXf W;
    transposed_product(Bp, m, k, Q, W);
    G += (W.transpose() * W).cast<double>();
    wt.emplace_back(c, std::move(W));
  };
  BTFC_RETURN_IF_ERROR(run.pass(size_t(l * l), project, [&](double* d) { std::copy(G.data(), G.data() + G.size(), d); }));
  G = Eigen::Map<MatrixXd>(buf.data(), l, l);
  run.release();

  MatrixXd E;
  SvdResult r = spectrum_of(G, l, energy, opt, "randomized (streamed)", E);
  const Index rank = r.S.size();
  const MatrixXd Ek = E.leftCols(rank);
  r.U = (Q.cast<double>() * Ek).cast<float>();
  // SxV rows of the owned texels, summed (disjoint rows: exact) into process 0.
  MatrixXfR sxv = MatrixXfR::Zero(Index(n), rank);
  const MatrixXf Ekf = Ek.cast<float>();
  for (auto& [c, W] : wt) sxv.middleRows(Index(src.chunk_first(c)), W.rows()) = W * Ekf;
  wt.clear();
  BTFC_RETURN_IF_ERROR(run.finish(r, sxv, stats_out));
  return r;
}

}  // namespace btfc::fmf
