// Local PCA of per-texel ABRDFs (Kambhatla-Leen style iterative clustering, as used by
// Mueller et al. and seed 002 section 3) for the lpca codec.
//
// Algorithm:
//  1. Seeding: k-means++ (seeded by ctx.seed) on a 32-dimensional Gaussian sketch of the
//     ABRDFs (Johnson-Lindenstrauss: distances are preserved to ~25 %, enough for seeding; exact
//     k-means++ would stream the whole BTF once per cluster). Every texel joins its nearest seed.
//  2. Repeat up to `iters` times:
//     a. PCA step, per cluster (clusters in parallel, largest first; cluster_pca.h): mean +
//        `components` eigen-BRDFs of the centered members. A subspace of width c + 8 comes from
//        the float Gram matrix of the smaller side (eigen-decomposed in double) when that side
//        is <= 384, else from one subspace iteration started from the previous step's Ritz
//        vectors (two from random vectors for a new cluster), streamed over the members in
//        blocks; Rayleigh-Ritz in double then gives the best rank-c basis in it. The previous basis, with the new
//        mean, is scored in the same pass and kept when it reconstructs the members better, so
//        this step never increases the error even though the subspace is approximate. The total
//        squared error after this step is recorded.
//     b. Stop if this was the last iteration or the previous assignment step changed nothing.
//     c. Assignment step (assign.h): the error of texel x in cluster k is
//        ||x - mu_k||^2 - ||E_k^T (x - mu_k)||^2 (orthonormal E_k). Clusters that provably
//        cannot beat the texel's own (a triangle-inequality bound from its reconstruction and
//        residual) are skipped; the others are scored from float projections onto [mu_k E_k]
//        (OpenCL kernel or C++ reference). A texel moves to the best one only when it is better
//        by more than the projections' rounding margin (1e-5 of ||x||^2 + ||mu||^2), so float
//        noise cannot make the error grow or the assignment oscillate.
//     d. Empty clusters are re-seeded with the worst-reconstructed texels taken from clusters
//        that keep at least one member; with fewer texels than clusters some stay empty.
//  Per-iteration error is therefore non-increasing (up to float rounding of the sums).
//  Contracts: deterministic for a given seed; no NaN for all-zero or constant inputs (a cluster
//  whose centered data is zero gets zero eigen-BRDFs); empty clusters are dropped from the result
//  (cluster ids compacted), so every returned cluster has >= 1 member.
#pragma once
#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "core/btf.h"
#include "core/progress.h"
#include "core/status.h"

namespace btfc::lpca {

using MatrixXfR = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

struct FitOptions {
  int clusters = 32;
  int components = 8;
  int iters = 10;
  uint64_t seed = 1;
  bool prune = true;  // skip clusters that cannot win in the assignment step (assign.h); false for tests
  Progress* progress = nullptr;
};

struct FitResult {
  int clusters = 0;                   // used (non-empty) clusters K
  int components = 0;                 // c per cluster (zero-padded when a cluster has lower rank)
  std::vector<uint32_t> cluster_of;   // [texels] -> [0, K)
  MatrixXfR table;                    // [K * (c + 1)] x abrdf_size: row k*(c+1) = mean, then E_k1..E_kc
  MatrixXfR weights;                  // [texels] x c: E^T (x - mu) for the texel's cluster
  std::vector<double> sq_error;       // total squared error after each PCA step
  std::vector<int> changes;           // texels moved by each assignment step (+ re-seeds)
  int reseeded = 0;                   // empty clusters re-seeded, all iterations
  double total_energy = 0;            // ||B||_F^2
  bool converged = false;             // an assignment step changed nothing
  double assign_seconds = 0;          // wall time in assignment steps (kernel or C++ reference)
  int64_t assign_scored = 0;          // (texel, cluster) pairs scored in all assignment steps
  int64_t assign_exhaustive = 0;      // ... and how many an exhaustive step would have scored
};

Result<FitResult> fit_local_pca(const Btf& btf, const FitOptions& opt);

}  // namespace btfc::lpca
