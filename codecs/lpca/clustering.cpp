// Local PCA clustering for lpca; see clustering.h for the algorithm and its contracts.
#include "codecs/lpca/clustering.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <numeric>
#include <random>
#include <omp.h>

#include <Eigen/Dense>

#include "codecs/lpca/cluster_pca.h"
#include "codecs/lpca/assign.h"
#include "core/blas_env.h"

namespace btfc::lpca {
namespace {

using Eigen::Index;
using MapCF = Eigen::Map<const Eigen::MatrixXf>;  // the BTF as d x N, column-major (core/btf.h)

using MatF = Eigen::MatrixXf;

constexpr int k_sketch_dim = 32;
constexpr double k_move_margin = 1e-5;  // relative rounding margin of the float GEMM errors

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

  std::vector<ClusterBasis> cls(static_cast<size_t>(K));
  MatrixXfR weights = MatrixXfR::Zero(N, c);
  std::vector<PcaWorkspace> ws(static_cast<size_t>(omp_get_max_threads()));
  MatF omega;
  AssignWorkspace aws;
  std::vector<uint32_t> prev_assign;
  MatrixXfR proj(N, c + k_oversample);  // raw projections onto the texel's cluster's Ritz basis (cluster_pca.h)
  std::vector<uint8_t> proj_ok(static_cast<size_t>(N), 0);
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
    // inside (core/blas_env.h). With fewer clusters than 2 x threads, one at a time with
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
      const SingleThreadedBlas one_blas_thread(outer);  // the OpenMP threads are the parallelism
#pragma omp parallel for schedule(dynamic, 1) if (outer)
      for (size_t j = 0; j < by_size.size(); ++j) {
        const int k = by_size[j];
        pca_step(X, order.data() + start[size_t(k)], start[size_t(k) + 1] - start[size_t(k)], c, omega,
                 ws[size_t(omp_get_thread_num())], cls[size_t(k)], weights, err, proj, proj_ok);
      }
    }
    res.sq_error.push_back(std::accumulate(err.begin(), err.end(), 0.0));
    if (opt.progress) opt.progress->advance();
    if (it + 1 == opt.iters) break;
    const auto ta = std::chrono::steady_clock::now();
    prev_assign = assign;
    BTFC_ASSIGN_OR_RETURN(AssignStats as, assign_step(X, cls, c, x2, weights, k_move_margin, opt.prune, assign, err, aws));
    int moved = as.moved;
    res.assign_scored += as.scored;
    res.assign_exhaustive += as.exhaustive;
    res.assign_seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - ta).count();
    moved += reseed_empty(assign, err, K, res.reseeded);
    for (Index t = 0; t < N; ++t)
      if (assign[size_t(t)] != prev_assign[size_t(t)]) proj_ok[size_t(t)] = 0;  // projections onto the old cluster's U
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
