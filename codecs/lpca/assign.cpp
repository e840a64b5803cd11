// The pruned assignment step of the lpca clustering; see assign.h.
#include "codecs/lpca/assign.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

#include "core/blas_env.h"

namespace btfc::lpca {
namespace {

using Eigen::Index;
using MapCF = Eigen::Map<const Eigen::MatrixXf>;

constexpr Index k_max_gram_cols = 4096;                // K (c + 1) above which no bound is computed (G > 128 MB)
constexpr size_t k_range_bytes = size_t(256) << 20;  // texels per batch: the device's allocation limit is 1-2 GiB
constexpr int k_group = 8;                             // texels per group (the kernel's register blocking)

// Candidate bit sets of every texel (words per texel), from the bound of assign.h.
void find_candidates(const std::vector<ClusterBasis>& cls, int c, const std::vector<double>& x2, const MatrixXfR& weights,
                     double margin, bool prune, const std::vector<uint32_t>& assign, const std::vector<double>& err,
                     const std::vector<double>& mu2, AssignWorkspace& ws, Index words) {
  const Index K = Index(cls.size()), cols = c + 1, M = K * cols, N = Index(assign.size());
  ws.masks.assign(size_t(N * words), 0);
  const bool bound = prune && M <= k_max_gram_cols;
  Eigen::MatrixXd G;
  if (bound) {
    const Eigen::MatrixXd Wd = ws.W.cast<double>();
    G.noalias() = Wd.transpose() * Wd;
  }
  SingleThreadedBlas one_blas_thread;  // the per-texel products below run inside OpenMP threads
#pragma omp parallel
  {
    Eigen::VectorXd w(c), y(M);
#pragma omp for schedule(static)
    for (Index t = 0; t < N; ++t) {
      const Index a = Index(assign[size_t(t)]);
      uint64_t* m = ws.masks.data() + t * words;
      if (!bound) {
        for (Index k = 0; k < K; ++k)
          if (k != a && cls[size_t(k)].valid) m[k / 64] |= uint64_t(1) << (k % 64);
        continue;
      }
      const Index ma = a * cols;
      w = weights.row(t).transpose().cast<double>();
      y.noalias() = G.middleCols(ma + 1, c) * w;  // W^T (E_a^T w): every vector against p - mu_a
      const double pa = w.dot(y.segment(ma + 1, c)), ea = err[size_t(t)];
      for (Index k = 0; k < K; ++k) {
        if (k == a || !cls[size_t(k)].valid) continue;
        const Index mk = k * cols;
        // v = p - mu_k = (mu_a - mu_k) + E_a^T w; dist^2 = ||v||^2 - ||E_k v||^2.
        const double v2 = G(ma, ma) - 2 * G(ma, mk) + G(mk, mk) + 2 * (y(ma) - y(mk)) + pa;
        double u2 = 0;
        for (Index j = 1; j <= c; ++j) {
          const double u = G(mk + j, ma) - G(mk + j, mk) + y(mk + j);
          u2 += u * u;
        }
        const double s = margin * (x2[size_t(t)] + mu2[size_t(k)]);
        // Skipped iff dist(p, A_k) >= 2 ||r|| with both sides widened by s; NaN stays a candidate.
        if (!(v2 - u2 - s >= 4 * (ea + s))) m[k / 64] |= uint64_t(1) << (k % 64);
      }
    }
  }
}

}  // namespace

Result<AssignStats> assign_step(const MapCF& X, const std::vector<ClusterBasis>& cls, int c, const std::vector<double>& x2,
                                const MatrixXfR& weights, double margin, bool prune, std::vector<uint32_t>& assign,
                                std::vector<double>& err, AssignWorkspace& ws) {
  const Index d = X.rows(), N = X.cols(), K = Index(cls.size()), cols = c + 1, words = (K + 63) / 64;
  ws.W.resize(d, K * cols);
  ws.W.setZero();
  std::vector<double> mu2(size_t(K), -1.0), muE(size_t(K * c), 0.0);  // mu2 -1: no basis
  int valid = 0;
  for (Index k = 0; k < K; ++k) {
    const ClusterBasis& cl = cls[size_t(k)];
    if (!cl.valid) continue;
    ++valid;
    ws.W.col(k * cols) = cl.mean;
    ws.W.middleCols(k * cols + 1, c) = cl.E.transpose();
    mu2[size_t(k)] = cl.mean.cast<double>().squaredNorm();
    for (int j = 0; j < c; ++j) muE[size_t(k * c + j)] = cl.E.row(j).cast<double>().dot(cl.mean.cast<double>());
  }
  AssignStats st;
  st.exhaustive = int64_t(N) * std::max(0, valid - 1);
  find_candidates(cls, c, x2, weights, margin, prune, assign, err, mu2, ws, words);
  lpca_cl::fill_projection_table(ws.W.data(), d, int(K), c, ws.table);
  const size_t stride = size_t(ws.table.V);

  const Index range = std::clamp<Index>(Index(k_range_bytes / (size_t(d) * 4)), k_group, std::max<Index>(N, k_group));
  std::vector<uint32_t> list;
  std::vector<uint8_t> real;  // texels of each group that are not padding
  for (Index t0 = 0; t0 < N; t0 += range) {
    const Index nt = std::min(range, N - t0);
    auto mask = [&](uint32_t i) { return ws.masks.data() + (t0 + Index(i)) * words; };
    list.clear();
    for (Index i = 0; i < nt; ++i) {
      const uint64_t* m = mask(uint32_t(i));
      if (std::any_of(m, m + words, [](uint64_t v) { return v != 0; })) list.push_back(uint32_t(i));
    }
    std::sort(list.begin(), list.end(), [&](uint32_t i, uint32_t j) {
      const uint32_t ai = assign[size_t(t0 + i)], aj = assign[size_t(t0 + j)];
      if (ai != aj) return ai < aj;
      for (Index wd = 0; wd < words; ++wd)
        if (mask(i)[wd] != mask(j)[wd]) return mask(i)[wd] < mask(j)[wd];
      return i < j;
    });
    lpca_cl::GroupBatch b;
    b.X = X.data() + t0 * d, b.nt = nt;
    b.cand_off.push_back(0);
    real.clear();
    std::vector<uint64_t> uni(static_cast<size_t>(words));
    for (size_t i0 = 0; i0 < list.size();) {
      size_t i1 = i0 + 1;
      while (i1 < list.size() && i1 - i0 < size_t(k_group) && assign[size_t(t0 + list[i1])] == assign[size_t(t0 + list[i0])]) ++i1;
      std::fill(uni.begin(), uni.end(), 0);
      for (size_t i = i0; i < i0 + size_t(k_group); ++i) {
        const uint32_t tex = list[std::min(i, i1 - 1)];  // short groups repeat their last texel
        b.texels.push_back(tex);
        for (Index wd = 0; wd < words; ++wd) uni[size_t(wd)] |= mask(tex)[wd];
      }
      for (Index k = 0; k < K; ++k)
        if (uni[size_t(k / 64)] >> (k % 64) & 1) b.cand.push_back(uint32_t(k));
      b.cand_off.push_back(uint32_t(b.cand.size()));
      real.push_back(uint8_t(i1 - i0));
      st.scored += int64_t(i1 - i0) * int64_t(b.cand_off.back() - b.cand_off[b.cand_off.size() - 2]);
      i0 = i1;
    }
    if (b.cand.empty()) continue;
    if (ws.P.size() < b.cand.size() * k_group * stride) ws.P.resize(b.cand.size() * k_group * stride);
    BTFC_RETURN_IF_ERROR(lpca_cl::project(ws.table, b, ws.P.data()));
    // Selection in double, as the exhaustive step did: e_k from the projections, move on a
    // margin over the texel's current error.
    int moved = 0;
    const int64_t groups = int64_t(b.groups());
#pragma omp parallel for schedule(static) reduction(+ : moved)
    for (int64_t g = 0; g < groups; ++g) {
      for (int i = 0; i < real[size_t(g)]; ++i) {
        const size_t t = size_t(t0) + b.texels[size_t(g) * k_group + size_t(i)];
        double best = std::numeric_limits<double>::infinity();
        uint32_t best_k = assign[t];
        for (uint32_t p = b.cand_off[size_t(g)]; p < b.cand_off[size_t(g) + 1]; ++p) {
          const uint32_t k = b.cand[p];
          const float* pr = ws.P.data() + (size_t(p) * k_group + size_t(i)) * stride;
          double e = x2[t] - 2.0 * double(pr[0]) + mu2[k];
          for (int j = 0; j < c; ++j) {
            const double q = double(pr[1 + j]) - muE[size_t(k) * size_t(c) + size_t(j)];
            e -= q * q;
          }
          e = std::max(0.0, e);
          if (e < best) best = e, best_k = k;
        }
        if (best_k != assign[t] && best < err[t] - margin * (x2[t] + mu2[best_k])) {
          assign[t] = best_k;
          err[t] = best;
          ++moved;
        }
      }
    }
    st.moved += moved;
  }
  return st;
}

}  // namespace btfc::lpca
