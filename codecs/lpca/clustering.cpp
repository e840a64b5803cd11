// Local PCA clustering for lpca; see clustering.h for the algorithm and its contracts.
#include "codecs/lpca/clustering.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <numeric>
#include <optional>
#include <random>
#include <omp.h>

#include <Eigen/Dense>

#include "codecs/fmf/svd.h"
#include "codecs/lpca/lpca_cl.h"
#include "core/blas_env.h"

namespace btfc::lpca {
namespace {

using Eigen::Index;
using MapCF = Eigen::Map<const Eigen::MatrixXf>;  // the BTF as d x N, column-major (core/btf.h)

using MatF = Eigen::MatrixXf;
using MatD = Eigen::MatrixXd;
using MapF = Eigen::Map<Eigen::MatrixXf>;

constexpr int k_sketch_dim = 32;
constexpr Index k_exact_svd_limit = 384;  // Gram side up to which the exact (Gram) PCA is used
constexpr double k_move_margin = 1e-5;    // relative rounding margin of the float GEMM errors
constexpr int k_oversample = 8;           // subspace width l = c + k_oversample (Halko et al.)
constexpr int k_cold_power_iters = 2;     // subspace iterations from a random start
constexpr int k_warm_power_iters = 1;     // ... from the previous basis (clusters change little)
constexpr double k_rel_lambda_floor = 1e-12;  // (1e-6 sigma_max)^2: smaller components are float noise

struct Cluster {
  Eigen::VectorXf mean;  // d
  MatrixXfR E;           // c x d, orthonormal rows (or zero rows)
  bool valid = false;
};

// Moves the worst texels into empty clusters, one each, taking them only from clusters with
// at least two members. Returns the number of texels moved.
int reseed_empty(std::vector<uint32_t>& assign, const std::vector<double>& badness, int K, int& reseeded) {
  std::vector<int> count(size_t(K), 0);
  for (uint32_t a : assign) ++count[a];
  std::vector<int> empty;
  for (int k = K - 1; k >= 0; --k)
    if (count[size_t(k)] == 0) empty.push_back(k);
  if (empty.empty()) return 0;
  std::vector<size_t> order(assign.size());
  std::iota(order.begin(), order.end(), size_t(0));
  std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) { return badness[a] > badness[b]; });
  int moved = 0;
  for (size_t t : order) {
    if (empty.empty()) break;
    if (count[assign[t]] < 2) continue;
    --count[assign[t]];
    assign[t] = uint32_t(empty.back());
    ++count[size_t(empty.back())];
    empty.pop_back();
    ++moved;
  }
  reseeded += moved;
  return moved;
}

// k-means++ on a Gaussian sketch; returns the initial assignment and each texel's squared
// sketch distance to its seed (the badness used to re-seed duplicate seeds' empty clusters).
void seed_clusters(const MapCF& X, int K, uint64_t seed, std::vector<uint32_t>& assign, std::vector<double>& dist2) {
  const Index d = X.rows(), N = X.cols();
  std::mt19937_64 rng(seed);
  std::normal_distribution<float> gauss(0, 1);
  Eigen::MatrixXf omega(d, k_sketch_dim);
  for (Index i = 0; i < omega.size(); ++i) omega.data()[i] = gauss(rng) / std::sqrt(float(k_sketch_dim));
  Eigen::MatrixXf S(k_sketch_dim, N);
  S.noalias() = omega.transpose() * X;
  std::vector<Index> seeds;
  std::vector<double> D2(size_t(N), std::numeric_limits<double>::infinity());
  for (int k = 0; k < K; ++k) {
    Index pick = 0;
    const double total = k == 0 ? 0 : std::accumulate(D2.begin(), D2.end(), 0.0);
    if (total > 0 && std::isfinite(total)) {
      double r = std::uniform_real_distribution<double>(0, total)(rng);
      pick = N - 1;
      for (Index t = 0; t < N; ++t) {
        r -= D2[size_t(t)];
        if (r < 0) {
          pick = t;
          break;
        }
      }
    } else {
      pick = Index(std::uniform_int_distribution<uint64_t>(0, uint64_t(N - 1))(rng));
    }
    seeds.push_back(pick);
#pragma omp parallel for schedule(static)
    for (Index t = 0; t < N; ++t) D2[size_t(t)] = std::min(D2[size_t(t)], double((S.col(t) - S.col(pick)).squaredNorm()));
  }
  assign.assign(size_t(N), 0);
  dist2.assign(size_t(N), 0);
#pragma omp parallel for schedule(static)
  for (Index t = 0; t < N; ++t) {
    double best = std::numeric_limits<double>::infinity();
    for (int k = 0; k < K; ++k) {
      const double e = (S.col(t) - S.col(seeds[size_t(k)])).squaredNorm();
      if (e < best) best = e, assign[size_t(t)] = uint32_t(k);
    }
    dist2[size_t(t)] = best;
  }
}

// Buffers reused by every PCA step of the fit. Fresh large allocations are avoided on purpose:
// first touch of new memory runs at ~300 MB/s on the VMs btfc runs on, which made page faults
// ~15 % of the old per-cluster-temporaries encode. Eigen objects keep their storage when
// resized to the same size; the gather buffer only grows.
struct Workspace {
  FloatBuffer xc;       // d x cap: the current cluster's members, centered (column-major)
  Index cap = 0;
  Eigen::VectorXd acc;  // d: mean accumulator
  Eigen::VectorXf mean;
  Eigen::VectorXd xc2;  // n: ||x - mean||^2
  MatF QB;              // d x (l + c): subspace basis Q, then the previous basis E_old^T
  MatF Z, Wt, G;        // n x l, n x (l + c), Gram
  MatD Zd;              // orthonormalization scratch
};

// In-place orthonormal basis of the columns of Y: thin Householder QR in double (robust to
// rank-deficient Y, e.g. all-zero clusters; Q stays orthonormal whatever Y is).
void orthonormalize(Eigen::Ref<MatF> Y, MatD& scratch) {
  scratch = Y.cast<double>();
  Eigen::HouseholderQR<MatD> qr(scratch);
  scratch = qr.householderQ() * MatD::Identity(Y.rows(), Y.cols());
  Y = scratch.cast<float>();
}

using fmf::top_eigenpairs;

// PCA step for one cluster: new mean and basis, members' weights and squared errors.
//  1. An l-dimensional subspace Q (l = c + oversample) close to the top principal subspace:
//     exact from the float Gram matrix of the smaller side when that side is <= 384 (eigen-
//     decomposed in double), else by subspace (power) iteration started from the previous
//     basis plus random vectors (or random vectors only, for a new cluster).
//  2. Rayleigh-Ritz: W = Xc^T Q, eigen-decomposition of W^T W in double -> the best rank-c
//     basis within span(Q), orthonormal to float precision, with its weights.
//  3. The previous basis, with the new mean, is scored in the same GEMM as W; it is kept when
//     it reconstructs the members better. The new mean is optimal for any basis, so the step
//     never increases the error, whether the subspace was exact or approximate.
void pca_step(const MapCF& X, const Index* members, Index n, int c, const MatF& omega, Workspace& ws, Cluster& cl, MatrixXfR& weights,
              std::vector<double>& err) {
  const Index d = X.rows(), s = std::min(d, n), l = std::min<Index>(c + k_oversample, s);
  // Mean in double, by row blocks so each thread owns its part of the accumulator.
  ws.acc.setZero(d);
  const Index rb = 2048;
#pragma omp parallel for schedule(dynamic)
  for (Index r0 = 0; r0 < d; r0 += rb) {
    const Index nr = std::min(rb, d - r0);
    for (Index i = 0; i < n; ++i) ws.acc.segment(r0, nr) += X.col(members[i]).segment(r0, nr).cast<double>();
  }
  ws.mean = (ws.acc / double(n)).cast<float>();
  if (n > ws.cap) {
    ws.cap = n + n / 8;
    ws.xc = FloatBuffer();  // free first: peak memory stays one buffer
    ws.xc = FloatBuffer(size_t(d) * size_t(ws.cap));
  }
  MapF Xc(ws.xc.data(), d, n);
  ws.xc2.resize(n);
#pragma omp parallel for schedule(static)
  for (Index i = 0; i < n; ++i) {
    Xc.col(i) = X.col(members[i]) - ws.mean;
    ws.xc2(i) = Xc.col(i).cast<double>().squaredNorm();
  }

  // 1. The subspace Q = QB.leftCols(l).
  const Index extra = cl.valid ? c : 0;
  ws.QB.resize(d, l + extra);
  auto Q = ws.QB.leftCols(l);
  Eigen::VectorXd lambda;
  MatD V;
  if (s <= k_exact_svd_limit || l == s) {
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
  } else {
    // Start: the previous basis and l - c random vectors (warm), or l random vectors (cold).
    const Index keep = cl.valid ? std::min<Index>(c, l) : 0;
    if (keep) Q.leftCols(keep) = cl.E.topRows(keep).transpose();
    Q.rightCols(l - keep) = omega.leftCols(l - keep);
    const int q = cl.valid ? k_warm_power_iters : k_cold_power_iters;
    for (int it = 0; it < q; ++it) {
      ws.Z.noalias() = Xc.transpose() * Q;  // n x l
      orthonormalize(ws.Z, ws.Zd);
      Q.noalias() = Xc * ws.Z;  // d x l
      orthonormalize(Q, ws.Zd);
    }
  }
  if (extra) ws.QB.rightCols(c) = cl.E.transpose();

  // 2. Rayleigh-Ritz on span(Q), scoring the previous basis in the same pass over Xc.
  ws.Wt.noalias() = Xc.transpose() * ws.QB;  // n x (l + extra)
  const MatD Wd = ws.Wt.leftCols(l).cast<double>();
  top_eigenpairs(Wd.transpose() * Wd, l, lambda, V);
  Index kept = 0;  // components above the float-noise floor; the rest stay zero
  while (kept < std::min<Index>(c, l) && lambda(kept) > 0 && lambda(kept) > k_rel_lambda_floor * lambda(0)) ++kept;
  MatrixXfR E = MatrixXfR::Zero(c, d), W = MatrixXfR::Zero(n, c);
  if (kept) {
    E.topRows(kept).noalias() = (Q * V.leftCols(kept).cast<float>()).transpose();
    W.leftCols(kept) = (Wd * V.leftCols(kept)).cast<float>();
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

// Assignment step (lpca_cl.h: the OpenCL kernels or their C++ reference); returns the number of
// texels moved and fills `err` with the estimated error of each texel in its (new) cluster.
Result<int> assign_step(const MapCF& X, const std::vector<Cluster>& cls, int c, const std::vector<double>& x2,
                        std::vector<uint32_t>& assign, std::vector<double>& err, MatF& Wm) {
  const Index d = X.rows(), K = Index(cls.size()), cols = c + 1;
  Wm.resize(d, K * cols);
  Wm.setZero();
  lpca_cl::AssignProblem pr;
  pr.X = X.data(), pr.d = d, pr.N = X.cols(), pr.K = int(K), pr.c = c, pr.W = Wm.data(), pr.x2 = x2.data();
  pr.margin = k_move_margin;
  pr.mu2.assign(size_t(K), -1.0);  // -1: no basis, skipped
  pr.muE.assign(size_t(K) * size_t(c), 0.0);
  for (Index k = 0; k < K; ++k) {
    if (!cls[size_t(k)].valid) continue;
    Wm.col(k * cols) = cls[size_t(k)].mean;
    Wm.middleCols(k * cols + 1, c) = cls[size_t(k)].E.transpose();
    pr.mu2[size_t(k)] = cls[size_t(k)].mean.cast<double>().squaredNorm();
    for (int i = 0; i < c; ++i)
      pr.muE[size_t(k) * size_t(c) + size_t(i)] = cls[size_t(k)].E.row(i).cast<double>().dot(cls[size_t(k)].mean.cast<double>());
  }
  return lpca_cl::assign(pr, assign.data(), err.data());
}

}  // namespace

Result<FitResult> fit_local_pca(const Btf& btf, const FitOptions& opt) {
  const BtfDesc& desc = btf.desc();
  const Index d = Index(desc.abrdf_size()), N = Index(desc.num_texels());
  if (d == 0 || N == 0) return invalid_argument("lpca: empty BTF");
  const int K = opt.clusters, c = opt.components;
  if (K < 1 || c < 1) return invalid_argument("lpca: clusters and components must be >= 1");
  const MapCF X(btf.data(), d, N);
  FitResult res;
  std::vector<double> x2(static_cast<size_t>(N));
#pragma omp parallel for schedule(static)
  for (Index t = 0; t < N; ++t) x2[size_t(t)] = X.col(t).cast<double>().squaredNorm();
  res.total_energy = std::accumulate(x2.begin(), x2.end(), 0.0);

  std::vector<uint32_t> assign;
  std::vector<double> err;
  seed_clusters(X, K, opt.seed, assign, err);
  reseed_empty(assign, err, K, res.reseeded);

  std::vector<Cluster> cls(static_cast<size_t>(K));
  MatrixXfR weights = MatrixXfR::Zero(N, c);
  std::vector<Workspace> ws(static_cast<size_t>(omp_get_max_threads()));
  MatF omega;
  MatF Wm;  // the assignment step's stacked [mu_k E_k^T], reused
  std::vector<Index> order(static_cast<size_t>(N));  // texels sorted by cluster (counting sort)
  std::vector<Index> start(size_t(K) + 1);
  const Index l_max = std::min<Index>(c + k_oversample, d);
  if (opt.progress) opt.progress->start("lpca clustering", uint64_t(opt.iters));
  for (int it = 0; it < opt.iters; ++it) {
    std::fill(start.begin(), start.end(), 0);
    for (Index t = 0; t < N; ++t) ++start[assign[size_t(t)] + 1];
    for (int k = 0; k < K; ++k) start[size_t(k) + 1] += start[size_t(k)];
    {
      std::vector<Index> pos(start.begin(), start.end() - 1);
      for (Index t = 0; t < N; ++t) order[size_t(pos[assign[size_t(t)]]++)] = t;
    }
    // Gaussian start vectors of this iteration's subspace iterations (deterministic by seed).
    std::mt19937_64 rng(opt.seed * 1000003ull + uint64_t(it) * 4099u);
    std::normal_distribution<float> gauss(0, 1);
    omega.resize(d, l_max);
    for (Index i = 0; i < omega.size(); ++i) omega.data()[i] = gauss(rng);
    // Clusters in parallel, largest first, each on its own workspace with single-threaded Eigen
    // inside (see assign_step). With fewer clusters than 2 x threads, one at a time with
    // Eigen's own threading instead. Results do not depend on which thread ran a cluster.
    std::vector<int> by_size;
    for (int k = 0; k < K; ++k) {
      if (start[size_t(k) + 1] == start[size_t(k)]) cls[size_t(k)].valid = false;  // only when texels < clusters
      else by_size.push_back(k);
    }
    std::stable_sort(by_size.begin(), by_size.end(), [&](int a, int b) {
      return start[size_t(a) + 1] - start[size_t(a)] > start[size_t(b) + 1] - start[size_t(b)];
    });
    const bool outer = by_size.size() >= 2 * ws.size();
    {
      std::optional<SingleThreadedBlas> one_blas_thread;  // the OpenMP threads are the parallelism
      if (outer) one_blas_thread.emplace();
#pragma omp parallel for schedule(dynamic, 1) if (outer)
      for (size_t j = 0; j < by_size.size(); ++j) {
        const int k = by_size[j];
        pca_step(X, order.data() + start[size_t(k)], start[size_t(k) + 1] - start[size_t(k)], c, omega,
                 ws[size_t(omp_get_thread_num())], cls[size_t(k)], weights, err);
      }
    }
    res.sq_error.push_back(std::accumulate(err.begin(), err.end(), 0.0));
    if (opt.progress) opt.progress->advance();
    if (it + 1 == opt.iters) break;
    const auto ta = std::chrono::steady_clock::now();
    BTFC_ASSIGN_OR_RETURN(int moved, assign_step(X, cls, c, x2, assign, err, Wm));
    res.assign_seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - ta).count();
    moved += reseed_empty(assign, err, K, res.reseeded);
    res.changes.push_back(moved);
    if (moved == 0) {
      res.converged = true;
      break;
    }
  }
  if (opt.progress) opt.progress->finish();

  // Compact: drop clusters without members.
  std::vector<int> remap(size_t(K), -1);
  std::vector<int> count(size_t(K), 0);
  for (uint32_t a : assign) ++count[a];
  int used = 0;
  for (int k = 0; k < K; ++k)
    if (count[size_t(k)] > 0 && cls[size_t(k)].valid) remap[size_t(k)] = used++;
  res.clusters = used;
  res.components = c;
  res.table = MatrixXfR::Zero(Index(used) * (c + 1), d);
  for (int k = 0; k < K; ++k) {
    if (remap[size_t(k)] < 0) continue;
    const Index r0 = Index(remap[size_t(k)]) * (c + 1);
    res.table.row(r0) = cls[size_t(k)].mean.transpose();
    res.table.middleRows(r0 + 1, c) = cls[size_t(k)].E;
  }
  res.cluster_of.resize(size_t(N));
  for (Index t = 0; t < N; ++t) res.cluster_of[size_t(t)] = uint32_t(remap[assign[size_t(t)]]);
  res.weights = std::move(weights);
  return res;
}

}  // namespace btfc::lpca
