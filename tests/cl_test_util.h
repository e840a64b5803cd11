// Helpers of the OpenCL-vs-reference tests (cl_test.cpp, cl_kernels_test.cpp): random fmf factors
// in the kernels' packed layout and the relative difference the tolerances are stated in.
#pragma once
#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "codecs/fmf/fmf_cl.h"

namespace btfc::test {

// max |a - b| / max |b|: relative to the data's scale (1e-30 keeps all-zero data finite).
inline double rel_diff(const float* a, const float* b, size_t n) {
  double d = 0, m = 1e-30;
  for (size_t i = 0; i < n; ++i) d = std::max(d, double(std::fabs(a[i] - b[i]))), m = std::max(m, double(std::fabs(b[i])));
  return d / m;
}
inline double rel_diff(const std::vector<float>& a, const std::vector<float>& b) { return rel_diff(a.data(), b.data(), b.size()); }

// Uniform random factors of a C-term model over nL x nV directions and `texels` texels. dfmf's
// SxV is scaled by 0.3 so that exp() of its sums stays in a range where float relative error
// means something.
inline fmf_cl::PackedFactors random_factors(int mode, int C, int nL, int nV, int texels, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-1, 1);
  fmf_cl::PackedFactors f;
  f.mode = mode, f.C = C, f.nL = nL, f.nV = nV, f.texels = texels;
  f.blocks = mode == BTFC_FMF_RGB ? 1 : 3;
  f.rows_per_block = mode == BTFC_FMF_RGB ? 3 * nL * nV : nL * nV;
  f.U.resize(size_t(f.blocks) * f.rows_per_block * C);
  f.SxV.resize(size_t(f.blocks) * texels * C);
  for (float& x : f.U) x = u(rng) / std::sqrt(float(C));
  for (float& x : f.SxV) x = u(rng) * (mode == BTFC_FMF_RGB ? 1.0f : 0.3f);
  return f;
}

}  // namespace btfc::test
