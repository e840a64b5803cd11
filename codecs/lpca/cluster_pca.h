// The PCA step of lpca's local-PCA clustering (clustering.h, step 2a) for one cluster: new mean
// and c eigen-BRDFs of the cluster's members, their weights and squared errors.
//
// Subspace: an l-dimensional subspace Q (l = c + 8, Halko et al.'s oversampling) close to the
// top principal subspace of the centered members, then Rayleigh-Ritz in it (double) for the best
// rank-c basis E within span(Q) and the members' weights.
//  - Small clusters (n or d <= 384, or l = min(n, d)): Q exact from the Gram matrix of the smaller
//    side, on a gathered copy of the members (<= 384 x 79 KB for Bonn-size ABRDFs).
//  - Large clusters: one subspace iteration per step, streaming the members in blocks of 64
//    columns copied from the BTF (no cluster-sized copy is written). Its start is the previous
//    step's l Ritz vectors U, whose projections the members already have: kept from that step's
//    final pass (`proj`), computed first for members that moved in. So Z = Xc^T U costs no pass;
//    Q' = Xc Z is formed from the raw columns (and sums the mean on the way), its mean share
//    subtracted afterwards (Xc Z = X Z - mu 1^T Z); the final projection pass centers
//    explicitly (its weights and errors are what is stored). 2 passes over the members per step,
//    where gather + 5 passes were before. Without Ritz vectors (a new cluster, or one that was
//    small): one iteration from the previous basis plus l - c random vectors, or two from l
//    random vectors, each pass Z = Xc^T Q likewise from the raw columns.
// Monotonicity: the previous basis, with the new mean, is scored in the final pass and kept when
// it reconstructs the members better; the new mean is optimal for any basis. So a step never
// increases the cluster's error, however approximate the subspace.
// Deterministic: fixed block order and fixed-order sums, independent of the calling thread.
#pragma once
#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "core/btf.h"

namespace btfc::lpca {

using MatrixXfR = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

constexpr int k_oversample = 8;  // subspace width l = c + k_oversample (Halko et al.)

struct ClusterBasis {
  Eigen::VectorXf mean;  // d
  MatrixXfR E;           // c x d, orthonormal rows (or zero rows past the data's rank)
  Eigen::MatrixXf U;     // d x l Ritz basis of the last step (large clusters only, else no columns)
  bool valid = false;    // has a basis (a PCA step ran on >= 1 member)
};

// Buffers reused by every PCA step of a fit, one per thread. Fresh large allocations are avoided
// on purpose: first touch of new memory runs at ~300 MB/s on the VMs btfc runs on.
struct PcaWorkspace {
  FloatBuffer xc;       // d x cap: the gathered members (small clusters) or one block
  Eigen::Index cap = 0;
  Eigen::VectorXd acc;  // d: mean accumulator
  Eigen::VectorXf mean;
  Eigen::VectorXd xc2;  // n: ||x - mean||^2
  Eigen::MatrixXf QB;   // d x (l + c): subspace basis Q, then the previous basis E^T
  Eigen::MatrixXf Z, Wt, G;
  Eigen::MatrixXd Zd;   // orthonormalization scratch
};

// X: the BTF as d x N, column-major (core/btf.h). members: n >= 1 distinct texel indices,
// ascending (runs of consecutive texels are then read in place). omega: d x >= l Gaussian start
// vectors shared by all clusters of an iteration. Writes weights.row(t) (c values) and err[t]
// for every member t and updates cl. proj (N x (c + k_oversample)) and proj_ok (N) carry each
// texel's raw projections onto its cluster's U between steps: the caller clears proj_ok[t]
// when t changes cluster.
void pca_step(const Eigen::Map<const Eigen::MatrixXf>& X, const Eigen::Index* members, Eigen::Index n, int c, const Eigen::MatrixXf& omega,
              PcaWorkspace& ws, ClusterBasis& cl, MatrixXfR& weights, std::vector<double>& err, MatrixXfR& proj,
              std::vector<uint8_t>& proj_ok);

}  // namespace btfc::lpca
