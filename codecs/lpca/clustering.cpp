// Local PCA clustering for lpca; see clustering.h for the algorithm and its contracts.
#include "codecs/lpca/clustering.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <random>

#include "codecs/fmf/svd.h"

namespace btfc::lpca {
namespace {

using Eigen::Index;
using MapCF = Eigen::Map<const Eigen::MatrixXf>;  // the BTF as d x N, column-major (core/btf.h)

constexpr int k_sketch_dim = 32;
constexpr Index k_exact_svd_limit = 384;  // Gram side up to which the exact SVD is cheaper
constexpr double k_move_margin = 1e-5;    // relative rounding margin of the float GEMM errors

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

// PCA step for one cluster: new mean and basis, members' weights and squared errors; keeps the
// old model when it reconstructs these members better.
Status pca_step(const MapCF& X, const std::vector<Index>& members, int c, uint64_t seed, Cluster& cl, MatrixXfR& weights,
                std::vector<double>& err) {
  const Index d = X.rows(), n = Index(members.size());
  Eigen::VectorXd acc = Eigen::VectorXd::Zero(d);
  const Index rb = 2048;
#pragma omp parallel for schedule(dynamic)
  for (Index r0 = 0; r0 < d; r0 += rb) {
    const Index nr = std::min(rb, d - r0);
    for (Index t : members) acc.segment(r0, nr) += X.col(t).segment(r0, nr).cast<double>();
  }
  const Eigen::VectorXf mean = (acc / double(n)).cast<float>();
  Eigen::MatrixXf Xc(d, n);
  Eigen::VectorXd xc2(n);
#pragma omp parallel for schedule(static)
  for (Index i = 0; i < n; ++i) {
    Xc.col(i) = X.col(members[size_t(i)]) - mean;
    xc2(i) = Xc.col(i).cast<double>().squaredNorm();
  }
  fmf::SvdOptions opt;
  opt.max_rank = c;
  opt.method = std::min(d, n) <= k_exact_svd_limit ? fmf::SvdMethod::exact : fmf::SvdMethod::randomized;
  opt.oversample = 8;
  opt.power_iters = 2;
  opt.seed = seed;
  BTFC_ASSIGN_OR_RETURN(fmf::SvdResult r, fmf::truncated_svd(Xc.data(), size_t(d), size_t(n), opt));
  const Index kept = std::min<Index>(r.U.cols(), c);
  MatrixXfR E = MatrixXfR::Zero(c, d), W = MatrixXfR::Zero(n, c);
  E.topRows(kept) = r.U.leftCols(kept).transpose();
  W.leftCols(kept) = r.SxV.leftCols(kept);
  if (!E.allFinite() || !W.allFinite()) {  // defensive: never let a degenerate SVD poison the model
    E.setZero();
    W.setZero();
  }
  std::vector<double> e_new(static_cast<size_t>(n));
  double sum_new = 0, sum_old = 0;
  for (Index i = 0; i < n; ++i) sum_new += e_new[size_t(i)] = std::max(0.0, xc2(i) - W.row(i).cast<double>().squaredNorm());
  if (cl.valid) {
    Xc.colwise() += mean - cl.mean;  // now centered at the old mean
    MatrixXfR Wo(n, c);
    Wo.noalias() = Xc.transpose() * cl.E.transpose();
    std::vector<double> e_old(static_cast<size_t>(n));
#pragma omp parallel for schedule(static)
    for (Index i = 0; i < n; ++i)
      e_old[size_t(i)] = std::max(0.0, Xc.col(i).cast<double>().squaredNorm() - Wo.row(i).cast<double>().squaredNorm());
    for (double e : e_old) sum_old += e;
    if (sum_old < sum_new) {
      for (Index i = 0; i < n; ++i) weights.row(members[size_t(i)]) = Wo.row(i), err[size_t(members[size_t(i)])] = e_old[size_t(i)];
      return {};
    }
  }
  cl.mean = mean;
  cl.E = std::move(E);
  cl.valid = true;
  for (Index i = 0; i < n; ++i) weights.row(members[size_t(i)]) = W.row(i), err[size_t(members[size_t(i)])] = e_new[size_t(i)];
  return {};
}

// Assignment step; returns the number of texels moved and fills `err` with the estimated
// error of each texel in its (new) cluster.
int assign_step(const MapCF& X, const std::vector<Cluster>& cls, int c, const std::vector<double>& x2,
                std::vector<uint32_t>& assign, std::vector<double>& err) {
  const Index d = X.rows(), N = X.cols(), K = Index(cls.size()), cols = c + 1;
  Eigen::MatrixXf Wm = Eigen::MatrixXf::Zero(d, K * cols);
  Eigen::MatrixXd muE = Eigen::MatrixXd::Zero(K, c);
  std::vector<double> mu2(size_t(K), 0);
  for (Index k = 0; k < K; ++k) {
    if (!cls[size_t(k)].valid) continue;
    Wm.col(k * cols) = cls[size_t(k)].mean;
    Wm.middleCols(k * cols + 1, c) = cls[size_t(k)].E.transpose();
    mu2[size_t(k)] = cls[size_t(k)].mean.cast<double>().squaredNorm();
    for (int i = 0; i < c; ++i) muE(k, i) = cls[size_t(k)].E.row(i).cast<double>().dot(cls[size_t(k)].mean.cast<double>());
  }
  int moved = 0;
  const Index tb = 2048;
  Eigen::MatrixXf P;
  for (Index t0 = 0; t0 < N; t0 += tb) {
    const Index nb = std::min(tb, N - t0);
    P.noalias() = X.middleCols(t0, nb).transpose() * Wm;  // nb x K(c+1), Eigen-parallel
#pragma omp parallel for schedule(static) reduction(+ : moved)
    for (Index i = 0; i < nb; ++i) {
      const size_t t = size_t(t0 + i);
      const uint32_t cur = assign[t];
      double best = std::numeric_limits<double>::infinity(), cur_e = best;
      uint32_t best_k = cur;
      for (Index k = 0; k < K; ++k) {
        if (!cls[size_t(k)].valid) continue;
        double e = x2[t] - 2.0 * P(i, k * cols) + mu2[size_t(k)];
        for (int j = 0; j < c; ++j) {
          const double p = double(P(i, k * cols + 1 + j)) - muE(k, j);
          e -= p * p;
        }
        e = std::max(0.0, e);
        if (uint32_t(k) == cur) cur_e = e;
        if (e < best) best = e, best_k = uint32_t(k);
      }
      if (best_k != cur && best < cur_e - k_move_margin * (x2[t] + mu2[best_k])) {
        assign[t] = best_k;
        err[t] = best;
        ++moved;
      } else {
        err[t] = std::isfinite(cur_e) ? cur_e : best;
      }
    }
  }
  return moved;
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
  if (opt.progress) opt.progress->start("lpca clustering", uint64_t(opt.iters));
  for (int it = 0; it < opt.iters; ++it) {
    std::vector<std::vector<Index>> members(static_cast<size_t>(K));
    for (Index t = 0; t < N; ++t) members[assign[size_t(t)]].push_back(t);
    for (int k = 0; k < K; ++k) {
      if (members[size_t(k)].empty()) {
        cls[size_t(k)].valid = false;  // only when there are fewer texels than clusters
        continue;
      }
      BTFC_RETURN_IF_ERROR(pca_step(X, members[size_t(k)], c, opt.seed * 1000003ull + uint64_t(it) * 4099u + uint64_t(k),
                                    cls[size_t(k)], weights, err));
    }
    res.sq_error.push_back(std::accumulate(err.begin(), err.end(), 0.0));
    if (opt.progress) opt.progress->advance();
    if (it + 1 == opt.iters) break;
    int moved = assign_step(X, cls, c, x2, assign, err);
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
