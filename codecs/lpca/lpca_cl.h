// lpca on OpenCL: the clustering's assignment step and the relighting (kernels/lpca.cl), each
// with the plain C++ reference it is tested against and that runs on the CPU path.
//
// Assignment (clustering.h step c): for every texel x and cluster k, the reconstruction error
//   e_k = ||x||^2 - 2 <x, mu_k> + ||mu_k||^2 - sum_j (<x, E_kj> - <mu_k, E_kj>)^2
// from the projections P = X^T W (W = the stacked [mu_k E_k^T], d x K (c + 1)), then the best
// cluster with a move margin. Reference: one float GEMM per texel block (Eigen, through
// OpenBLAS) and the selection in double. Kernel: lpca_project (register-blocked projection,
// direction chunks kept in cache) and lpca_select (the same selection in double; needs
// cl_khr_fp64, which PoCL has). P differs from the GEMM's by float summation order only, so
// assignments agree except where two clusters are within rounding of each other.
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

struct AssignProblem {
  const float* X = nullptr;  // texel-major ABRDFs: texel t at X + t d
  int64_t d = 0, N = 0;
  int K = 0, c = 0;
  const float* W = nullptr;           // d x K (c + 1), column-major: column k (c + 1) = mu_k, then E_k1..E_kc
  std::vector<double> mu2;            // K: ||mu_k||^2, or -1 for a cluster without a basis (skipped)
  std::vector<double> muE;            // K x c: <mu_k, E_kj>
  const double* x2 = nullptr;         // N: ||x_t||^2
  double margin = 1e-5;               // relative move margin
};

// Both update assign[t] (moves only) and err[t] (error in the texel's resulting cluster) and
// return the number of texels moved.
int assign_reference(const AssignProblem& p, uint32_t* assign, double* err);
Result<int> assign_cl(const AssignProblem& p, uint32_t* assign, double* err);
// assign_cl when OpenCL is in use (falling back under --device auto), else the reference.
Result<int> assign(const AssignProblem& p, uint32_t* assign, double* err);

// Relighting of every texel: cluster [n], weights [n x c] row-major, L [K (c + 1) x 3].
void relight_reference(std::span<const uint32_t> cluster, const float* W, int c, const float* L, float* out_rgb);
Status relight_cl(std::span<const uint32_t> cluster, const float* W, int c, const float* L, size_t L_rows, float* out_rgb);
// relight_cl when OpenCL is in use (falling back under --device auto), else the reference.
Status relight(std::span<const uint32_t> cluster, const float* W, int c, const float* L, size_t L_rows, float* out_rgb);

}  // namespace btfc::lpca_cl
