// The PCA step of the lpca clustering; see cluster_pca.h.
#include "codecs/lpca/cluster_pca.h"

#include <algorithm>
#include <cmath>
#include <cstdint>

#include <Eigen/Dense>

#include "core/svd.h"

namespace btfc::lpca {
namespace {

using Eigen::Index;
using MatF = Eigen::MatrixXf;
using MatD = Eigen::MatrixXd;
using MapF = Eigen::Map<MatF>;
using MapCF = Eigen::Map<const MatF>;

constexpr Index k_exact_svd_limit = 384;  // Gram side up to which the exact (Gram) PCA is used
constexpr Index k_block = 64;             // members per streamed block (5 MB of Bonn-size ABRDFs)
constexpr int k_cold_power_iters = 2;     // subspace iterations from a random start
constexpr int k_warm_power_iters = 1;     // ... from the previous basis (clusters change little)
constexpr double k_rel_lambda_floor = 1e-12;  // (1e-6 sigma_max)^2: smaller components are float noise

// In-place orthonormal basis of the columns of Y: thin Householder QR in double (robust to
// rank-deficient Y, e.g. all-zero clusters; Q stays orthonormal whatever Y is).
void orthonormalize(Eigen::Ref<MatF> Y, MatD& scratch) {
  scratch = Y.cast<double>();
  Eigen::HouseholderQR<MatD> qr(scratch);
  scratch = qr.householderQ() * MatD::Identity(Y.rows(), Y.cols());
  Y = scratch.cast<float>();
}

// dst = x - mean over d values; returns ||dst||^2 summed in double. One pass, 16 floats at a
// time: Eigen's x.cast<double>().squaredNorm() ran at a third of this speed and was half of the
// projection pass's time.
double center(const float* x, const float* mean, float* dst, Index d) {
  using F8 = Eigen::Array<float, 8, 1>;
  using D8 = Eigen::Array<double, 8, 1>;
  D8 a0 = D8::Zero(), a1 = D8::Zero();
  Index i = 0;
  for (; i + 16 <= d; i += 16) {
    const F8 u = Eigen::Map<const F8>(x + i) - Eigen::Map<const F8>(mean + i);
    const F8 v = Eigen::Map<const F8>(x + i + 8) - Eigen::Map<const F8>(mean + i + 8);
    Eigen::Map<F8>(dst + i) = u, Eigen::Map<F8>(dst + i + 8) = v;
    const D8 ud = u.cast<double>(), vd = v.cast<double>();
    a0 += ud * ud, a1 += vd * vd;
  }
  double lanes[8];  // (a0 + a1).sum() draws a GCC 12 -Wuninitialized false positive from avx512fintrin.h
  Eigen::Map<D8> lane_map(lanes);
  lane_map = a0 + a1;
  double s = 0;
  for (double v : lanes) s += v;
  for (; i < d; ++i) {
    dst[i] = x[i] - mean[i];
    s += double(dst[i]) * double(dst[i]);
  }
  return s;
}

// ws.xc with room for d x cols floats (grows only; freed first so peak memory stays one buffer).
float* scratch(PcaWorkspace& ws, Index d, Index cols) {
  if (cols > ws.cap) {
    ws.cap = cols + cols / 8;
    ws.xc = FloatBuffer();
    ws.xc = FloatBuffer(size_t(d) * size_t(ws.cap));
  }
  return ws.xc.data();
}

// Calls f(i0, Xb) for the members in blocks of k_block columns, in order. Xb is the block copied
// into ws.xc (centered by ws.mean when `centered`, which also sets ws.xc2(i) = ||x_i - mean||^2),
// or the BTF itself when the block is a run of consecutive texels and needs no centering.
template <class F>
void for_blocks(const MapCF& X, const Index* members, Index n, PcaWorkspace& ws, bool centered, F&& f) {
  const Index d = X.rows();
  float* buf = scratch(ws, d, std::min(n, k_block));
  for (Index i0 = 0; i0 < n; i0 += k_block) {
    const Index nb = std::min(k_block, n - i0);
    const Index* m = members + i0;
    bool run = !centered;
    for (Index j = 1; j < nb && run; ++j) run = m[j] == m[0] + j;
    if (run) {
      f(i0, MapCF(X.data() + m[0] * d, d, nb));
      continue;
    }
    MapF Xb(buf, d, nb);
    for (Index j = 0; j < nb; ++j) {
      if (centered) ws.xc2(i0 + j) = center(X.col(m[j]).data(), ws.mean.data(), Xb.col(j).data(), d);
      else Xb.col(j) = X.col(m[j]);
    }
    f(i0, MapCF(buf, d, nb));
  }
}

// Exact subspace of a small cluster: gathers the centered members into ws.xc (d x n) and sets
// Q from the Gram matrix of the smaller side.
void exact_subspace(const MapCF& X, const Index* members, Index n, Index l, PcaWorkspace& ws, Eigen::Ref<MatF> Q) {
  const Index d = X.rows();
  ws.acc.setZero(d);
  for (Index i = 0; i < n; ++i) ws.acc += X.col(members[i]).cast<double>();
  ws.mean = (ws.acc / double(n)).cast<float>();
  MapF Xc(scratch(ws, d, n), d, n);
  ws.xc2.resize(n);
  for (Index i = 0; i < n; ++i) ws.xc2(i) = center(X.col(members[i]).data(), ws.mean.data(), Xc.col(i).data(), d);
  Eigen::VectorXd lambda;
  MatD V;
  if (n <= d) {  // texel side: G = Xc^T Xc, Q = orth(Xc V_l)
    ws.G.noalias() = Xc.transpose() * Xc;
    top_eigenpairs(ws.G.cast<double>(), l, lambda, V);
    Q.noalias() = Xc * V.cast<float>();
    orthonormalize(Q, ws.Zd);
  } else {  // direction side: G = Xc Xc^T, Q = its top eigenvectors
    ws.G.noalias() = Xc * Xc.transpose();
    top_eigenpairs(ws.G.cast<double>(), l, lambda, V);
    Q = V.cast<float>();
  }
}

// Streamed subspace iteration of a large cluster, from the start vectors already in Q; sets
// ws.mean (first pass). Z = Xc^T Q and Q = Xc Z come from the raw columns with the mean's share
// subtracted afterwards: the float cancellation (~1e-6 relative) only perturbs the start of
// Rayleigh-Ritz, whose own pass centers explicitly.
void streamed_subspace(const MapCF& X, const Index* members, Index n, int q, PcaWorkspace& ws, Eigen::Ref<MatF> Q) {
  const Index d = X.rows(), l = Q.cols();
  ws.Z.resize(n, l);
  for (int it = 0; it < q; ++it) {
    const bool first = it == 0;
    if (first) ws.acc.setZero(d);
    for_blocks(X, members, n, ws, false, [&](Index i0, const MapCF& Xb) {
      if (first)
        for (Index j = 0; j < Xb.cols(); ++j) ws.acc += Xb.col(j).cast<double>();
      ws.Z.middleRows(i0, Xb.cols()).noalias() = Xb.transpose() * Q;
    });
    if (first) ws.mean = (ws.acc / double(n)).cast<float>();
    const Eigen::RowVectorXf muQ = ws.mean.transpose() * Q;
    ws.Z.rowwise() -= muQ;
    orthonormalize(ws.Z, ws.Zd);
    const Eigen::RowVectorXf zsum = ws.Z.colwise().sum();
    Q.setZero();
    for_blocks(X, members, n, ws, false, [&](Index i0, const MapCF& Xb) { Q.noalias() += Xb * ws.Z.middleRows(i0, Xb.cols()); });
    Q.noalias() -= ws.mean * zsum;
    orthonormalize(Q, ws.Zd);
  }
}

// One streamed subspace iteration of a large cluster from its previous Ritz basis U, whose
// projections the members already have (proj: raw <x, U_j>, from the previous step or, for
// members that moved in, computed here first): Z = Xc^T U needs no pass, only Q = Xc Z does,
// and that pass also sums the mean.
void ritz_subspace(const MapCF& X, const Index* members, Index n, const MatF& U, MatrixXfR& proj, std::vector<uint8_t>& proj_ok,
                   PcaWorkspace& ws, Eigen::Ref<MatF> Q) {
  const Index d = X.rows(), l = Q.cols();
  std::vector<Index> missing;
  for (Index i = 0; i < n; ++i)
    if (!proj_ok[size_t(members[i])]) missing.push_back(members[i]);
  for_blocks(X, missing.data(), Index(missing.size()), ws, false, [&](Index i0, const MapCF& Xb) {
    ws.G.noalias() = Xb.transpose() * U;
    for (Index j = 0; j < Xb.cols(); ++j) proj.row(missing[size_t(i0 + j)]).head(l) = ws.G.row(j);
  });
  ws.Z.resize(n, l);
  for (Index i = 0; i < n; ++i) ws.Z.row(i) = proj.row(members[i]).head(l);
  const Eigen::RowVectorXf mean_proj = (ws.Z.cast<double>().colwise().sum() / double(n)).cast<float>();  // mu^T U
  ws.Z.rowwise() -= mean_proj;
  orthonormalize(ws.Z, ws.Zd);
  const Eigen::RowVectorXf zsum = ws.Z.colwise().sum();
  ws.acc.setZero(d);
  Q.setZero();
  for_blocks(X, members, n, ws, false, [&](Index i0, const MapCF& Xb) {
    for (Index j = 0; j < Xb.cols(); ++j) ws.acc += Xb.col(j).cast<double>();
    Q.noalias() += Xb * ws.Z.middleRows(i0, Xb.cols());
  });
  ws.mean = (ws.acc / double(n)).cast<float>();
  Q.noalias() -= ws.mean * zsum;
  orthonormalize(Q, ws.Zd);
}

}  // namespace

void pca_step(const Eigen::Map<const Eigen::MatrixXf>& X, const Index* members, Index n, int c, const MatF& omega, PcaWorkspace& ws,
              ClusterBasis& cl, MatrixXfR& weights, std::vector<double>& err, MatrixXfR& proj, std::vector<uint8_t>& proj_ok) {
  const Index d = X.rows(), s = std::min(d, n), l = std::min<Index>(c + k_oversample, s);
  const Index extra = cl.valid ? c : 0;
  ws.QB.resize(d, l + extra);
  auto Q = ws.QB.leftCols(l);
  const bool exact = s <= k_exact_svd_limit || l == s;

  // 1. The subspace Q = QB.leftCols(l), and the mean.
  if (exact) {
    exact_subspace(X, members, n, l, ws, Q);
  } else if (cl.valid && cl.U.cols() == l && proj.cols() >= l) {
    ritz_subspace(X, members, n, cl.U, proj, proj_ok, ws, Q);
  } else {
    // Start: the previous basis and l - c random vectors (warm), or l random vectors (cold).
    const Index keep = cl.valid ? std::min<Index>(c, l) : 0;
    if (keep) Q.leftCols(keep) = cl.E.topRows(keep).transpose();
    Q.rightCols(l - keep) = omega.leftCols(l - keep);
    streamed_subspace(X, members, n, cl.valid ? k_warm_power_iters : k_cold_power_iters, ws, Q);
  }
  if (extra) ws.QB.rightCols(c) = cl.E.transpose();

  // 2. Rayleigh-Ritz on span(Q), scoring the previous basis in the same pass over the centered
  // members (which also gives their squared norms).
  ws.Wt.resize(n, l + extra);
  if (exact) {
    ws.Wt.noalias() = MapCF(ws.xc.data(), d, n).transpose() * ws.QB;
  } else {
    ws.xc2.resize(n);
    for_blocks(X, members, n, ws, true,
               [&](Index i0, const MapCF& Xb) { ws.Wt.middleRows(i0, Xb.cols()).noalias() = Xb.transpose() * ws.QB; });
  }
  Eigen::VectorXd lambda;
  MatD V;
  const MatD Wd = ws.Wt.leftCols(l).cast<double>();
  top_eigenpairs(Wd.transpose() * Wd, l, lambda, V);
  Index kept = 0;  // components above the float-noise floor; the rest stay zero
  while (kept < std::min<Index>(c, l) && lambda(kept) > 0 && lambda(kept) > k_rel_lambda_floor * lambda(0)) ++kept;
  // The Ritz basis U = Q V and the members' Ritz coordinates: the new basis is their top c; a
  // large cluster keeps U (and the members' raw projections onto it) to start the next step.
  const MatF U = Q * V.cast<float>();
  const MatD WV = Wd * V;
  MatrixXfR E = MatrixXfR::Zero(c, d), W = MatrixXfR::Zero(n, c);
  if (kept) {
    E.topRows(kept) = U.leftCols(kept).transpose();
    W.leftCols(kept) = WV.leftCols(kept).cast<float>();
  }
  if (!exact && proj.cols() >= l && U.allFinite() && WV.allFinite()) {
    const Eigen::RowVectorXd muU = ws.mean.transpose().cast<double>() * U.cast<double>();
    for (Index i = 0; i < n; ++i) {
      proj.row(members[i]).head(l) = (WV.row(i) + muU).cast<float>();
      proj_ok[size_t(members[i])] = 1;
    }
    cl.U = U;
  } else {
    cl.U.resize(d, 0);
  }
  if (!E.allFinite() || !W.allFinite()) {  // defensive: never let a degenerate step poison the model
    E.setZero();
    W.setZero();
  }
  // Sums in a fixed order (no floating-point OpenMP reduction): determinism by seed.
  double sum_new = 0, sum_old = 0;
  for (Index i = 0; i < n; ++i) sum_new += std::max(0.0, ws.xc2(i) - W.row(i).cast<double>().squaredNorm());
  if (extra) {
    for (Index i = 0; i < n; ++i) sum_old += std::max(0.0, ws.xc2(i) - ws.Wt.row(i).tail(c).cast<double>().squaredNorm());
    if (sum_old < sum_new) {  // 3. keep the previous basis (with the better, new mean)
      cl.mean = ws.mean;
      for (Index i = 0; i < n; ++i) {
        weights.row(members[i]) = ws.Wt.row(i).tail(c);
        err[size_t(members[i])] = std::max(0.0, ws.xc2(i) - ws.Wt.row(i).tail(c).cast<double>().squaredNorm());
      }
      return;
    }
  }
  cl.mean = ws.mean;
  cl.E = std::move(E);
  cl.valid = true;
  for (Index i = 0; i < n; ++i) {
    weights.row(members[i]) = W.row(i);
    err[size_t(members[i])] = std::max(0.0, ws.xc2(i) - W.row(i).cast<double>().squaredNorm());
  }
}

}  // namespace btfc::lpca
