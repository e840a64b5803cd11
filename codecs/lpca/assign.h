// The assignment step of lpca's local-PCA clustering (clustering.h, step 2c): each texel x moves
// to the cluster k with the lowest reconstruction error
//   e_k(x) = ||x - mu_k||^2 - ||E_k (x - mu_k)||^2      (E_k: c orthonormal rows)
// when that beats its own cluster a by more than the float margin. Done exhaustively this is one
// GEMM of all texels against all K (c + 1) vectors: 743 GFLOP per step for 256^2 texels of 19683
// values at 32 x 8, five times the PCA step. Here clusters that provably cannot win are skipped.
//
// Bound. Let p = mu_a + E_a^T w be x's reconstruction in its cluster (w = E_a (x - mu_a), the PCA
// step's weights) and r = x - p, so ||r||^2 = e_a (the PCA step's error). By the triangle
// inequality the distance from x to cluster k's affine subspace A_k is at least
// dist(p, A_k) - ||r||, so k can only beat a when dist(p, A_k) < 2 ||r||. p lies in the span of
// the means and bases, so with G = the Gram matrix of all K (c + 1) vectors (double),
// dist(p, A_k)^2 = ||p - mu_k||^2 - ||E_k (p - mu_k)||^2 costs O(c) per (texel, cluster) after
// one M x c product per texel. Slack of margin (||x||^2 + ||mu_k||^2) on both sides covers
// rounding (G is exact for the stored float vectors; E_k is orthonormal to float precision). On
// the synthetic BTFs 2.5-6 of 31 other clusters per texel survive (more in the first steps); at
// 256^2 texels and 32 x 8, 23 % of the (texel, cluster) pairs are scored, group unions included.
//
// Scoring. Survivors are scored as the exhaustive step scored every cluster: projections in
// float (lpca_cl.h: kernel lpca_project or its C++ reference), error in double. Per range of
// texels (the device's allocation limit), texels with candidates are sorted by (cluster,
// candidate set) and cut into groups of 8 of one cluster; a group is scored against the union of
// its texels' candidates, and each texel takes the best of them.
//
// Contract: the same moves as the exhaustive step up to float rounding (a skipped cluster has
// e_k >= e_a, so it is neither a winner nor better than the winner), hence the fit's error stays
// non-increasing. err[t] holds the texel's error in its cluster on entry (the PCA step's) and on
// exit (the scored error after a move). Deterministic (sorted groups, fixed-order selection).
// When the Gram matrix would be large (K (c + 1) > 4096) every cluster is a candidate.
#pragma once
#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "codecs/lpca/cluster_pca.h"
#include "codecs/lpca/lpca_cl.h"
#include "core/status.h"

namespace btfc::lpca {

struct AssignWorkspace {  // reused across steps
  Eigen::MatrixXf W;      // d x K (c + 1): [mu_k E_k^T]
  lpca_cl::ProjectionTable table;
  std::vector<float> P;
  std::vector<uint64_t> masks;  // candidate bit sets, N x ceil(K / 64) words
};

struct AssignStats {
  int moved = 0;
  int64_t scored = 0;      // (texel, cluster) pairs scored, group unions included
  int64_t exhaustive = 0;  // pairs the exhaustive step scores: texels x (valid clusters - 1)
};

// X: d x N column-major. weights: N x c, err: N, from the PCA step that ran on `assign`.
// prune = false scores every cluster (the exhaustive step, for tests).
Result<AssignStats> assign_step(const Eigen::Map<const Eigen::MatrixXf>& X, const std::vector<ClusterBasis>& cls, int c,
                                const std::vector<double>& x2, const MatrixXfR& weights, double margin, bool prune,
                                std::vector<uint32_t>& assign, std::vector<double>& err, AssignWorkspace& ws);

}  // namespace btfc::lpca
