// lpca on OpenCL: the clustering's assignment step and the relighting (kernels/lpca.cl), each
// with the plain C++ reference it is tested against and that runs on the CPU path.
//
// Assignment (clustering.h step c, assign.h): projections of texels onto candidate clusters
// [mu_k E_k^T]. The texels come in groups of 8, each group with a list of candidate clusters;
// for every (group, candidate k) pair p, texel i of the group and vector j < c + 1 of cluster k,
//   P[(p * 8 + i) * V + j] = <x_i, W_kj>,   V = c + 1 rounded up to a multiple of 3.
// Kernel lpca_project: lanes along the directions, a work-item keeps 8 texels x 3 vectors of
// float16 partial sums in registers (11 loads per 24 FMAs, no padded lanes); one launch per
// chunk of 1024 directions, so a group's texel chunks stay in L1 across its candidates.
// Reference: the same loops in C++. Float sums in another order: the two agree to rounding.
//
// Relighting (seed 002 eq. 2-3): out[t] = L[r0] + sum_i w[t][i] L[r0 + 1 + i], r0 = cluster(t)
// (c + 1), L = per table row, the view-blended dot products of its SH coefficients with the
// lighting (3 floats per row).
#pragma once
#include <cstdint>
#include <span>
#include <vector>

#include "core/status.h"

namespace btfc::lpca_cl {

// W = the stacked [mu_k E_k^T] in the kernel's layout: per cluster V vectors (zero vectors past
// c + 1), each d contiguous values: [k][j][r]. Filled once per assignment step.
struct ProjectionTable {
  int64_t d = 0;
  int K = 0, c = 0, V = 0;
  std::vector<float> vectors;
};
// W: d x K (c + 1), column-major: column k (c + 1) = mu_k, then E_k1..E_kc. Reuses t's storage
// when the shape is unchanged (fresh memory is slow to touch on the VMs btfc runs on).
void fill_projection_table(const float* W, int64_t d, int K, int c, ProjectionTable& t);

// One batch of groups over a range of texels (the device's allocation limit bounds a range).
struct GroupBatch {
  const float* X = nullptr;        // texels [0, nt) of the range, texel-major (texel t at X + t d)
  int64_t nt = 0;
  std::vector<uint32_t> texels;    // 8 per group, each < nt (a short group repeats a texel)
  std::vector<uint32_t> cand_off;  // groups + 1 offsets into cand
  std::vector<uint32_t> cand;      // the cluster of each (group, candidate) pair, < K
  size_t groups() const { return cand_off.empty() ? 0 : cand_off.size() - 1; }
};

// P: cand.size() x 8 x V floats.
void project_reference(const ProjectionTable& t, const GroupBatch& b, float* P);
Status project_cl(const ProjectionTable& t, const GroupBatch& b, float* P);
// project_cl when OpenCL is in use (falling back under --device auto), else the reference.
Status project(const ProjectionTable& t, const GroupBatch& b, float* P);

// Relighting of every texel: cluster [n], weights [n x c] row-major, L [K (c + 1) x 3].
void relight_reference(std::span<const uint32_t> cluster, const float* W, int c, const float* L, float* out_rgb);
Status relight_cl(std::span<const uint32_t> cluster, const float* W, int c, const float* L, size_t L_rows, float* out_rgb);
// relight_cl when OpenCL is in use (falling back under --device auto), else the reference.
Status relight(std::span<const uint32_t> cluster, const float* W, int c, const float* L, size_t L_rows, float* out_rgb);

}  // namespace btfc::lpca_cl
