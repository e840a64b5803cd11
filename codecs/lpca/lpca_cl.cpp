// lpca OpenCL host code and C++ references; see lpca_cl.h.
#include "codecs/lpca/lpca_cl.h"

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <limits>
#include <omp.h>

#include "core/cl_runtime.h"

namespace btfc::lpca_cl {
namespace {

// Directions per lpca_project launch: a group's 8 texel chunks (32 KB) stay in L1 while it
// runs through its candidates, each cluster's chunk (36 KB at 8 components) in L2.
constexpr int64_t k_chunk = 1024;
constexpr int k_vblock = 3;  // vectors per register block (8 texels x 3 vectors x float16)
using Lanes = Eigen::Array<float, 16, 1>;

}  // namespace

void fill_projection_table(const float* W, int64_t d, int K, int c, ProjectionTable& t) {
  const int V = (c + 1 + k_vblock - 1) / k_vblock * k_vblock;
  const size_t size = size_t(K) * size_t(V) * size_t(d);
  if (t.vectors.size() != size || t.V != V) t.vectors.assign(size, 0.0f);  // else the padding is still zero
  t.d = d, t.K = K, t.c = c, t.V = V;
#pragma omp parallel for schedule(static)
  for (int k = 0; k < K; ++k)
    std::copy_n(W + size_t(k) * size_t(c + 1) * size_t(d), size_t(c + 1) * size_t(d), t.vectors.data() + size_t(k) * size_t(V) * size_t(d));
}

void project_reference(const ProjectionTable& tb, const GroupBatch& b, float* P) {
  const int64_t d = tb.d, groups = int64_t(b.groups());
  const int V = tb.V;
#pragma omp parallel for schedule(dynamic, 4)
  for (int64_t g = 0; g < groups; ++g) {
    const float* x[8];
    for (int i = 0; i < 8; ++i) x[i] = b.X + size_t(b.texels[size_t(g) * 8 + size_t(i)]) * size_t(d);
    for (int64_t r0 = 0; r0 < d; r0 += k_chunk) {
      const int64_t rc = std::min(k_chunk, d - r0), r16 = rc / 16 * 16;
      for (uint32_t p = b.cand_off[size_t(g)]; p < b.cand_off[size_t(g) + 1]; ++p)
        for (int j = 0; j < V; j += k_vblock) {
          const float* w[k_vblock];
          for (int v = 0; v < k_vblock; ++v) w[v] = tb.vectors.data() + (size_t(b.cand[p]) * size_t(V) + size_t(j + v)) * size_t(d) + size_t(r0);
          // Eigen's fixed-size 16-float arrays stay in vector registers (plain float arrays with
          // omp simd ran 5x slower here).
          Lanes acc[8][k_vblock];
          for (auto& a : acc)
            for (Lanes& l : a) l.setZero();
          for (int64_t r = 0; r < r16; r += 16) {
            const Lanes w0 = Eigen::Map<const Lanes>(w[0] + r), w1 = Eigen::Map<const Lanes>(w[1] + r), w2 = Eigen::Map<const Lanes>(w[2] + r);
            for (int i = 0; i < 8; ++i) {
              const Lanes xv = Eigen::Map<const Lanes>(x[i] + r0 + r);
              acc[i][0] += xv * w0, acc[i][1] += xv * w1, acc[i][2] += xv * w2;
            }
          }
          for (int i = 0; i < 8; ++i)
            for (int v = 0; v < k_vblock; ++v) {
              float s = acc[i][v].sum();
              for (int64_t r = r16; r < rc; ++r) s = std::fma(x[i][r0 + r], w[v][r], s);
              float& q = P[(size_t(p) * 8 + size_t(i)) * size_t(V) + size_t(j + v)];
              q = r0 == 0 ? s : q + s;
            }
        }
    }
  }
}

Status project_cl(const ProjectionTable& tb, const GroupBatch& b, float* P) {
  const size_t groups = b.groups(), pairs = b.cand.size();
  if (groups == 0 || pairs == 0) return {};
  BTFC_ASSIGN_OR_RETURN(ocl::Runtime * rt, ocl::Runtime::get());
  BTFC_ASSIGN_OR_RETURN(ocl::Kernel kp, rt->kernel("lpca", "lpca_project"));
  const size_t d = size_t(tb.d), stride = size_t(tb.V);
  const auto in = ocl::Access::read_only;
  BTFC_ASSIGN_OR_RETURN(ocl::Buffer xb, ocl::Buffer::wrap(*rt, size_t(b.nt) * d * 4, const_cast<float*>(b.X), in));
  BTFC_ASSIGN_OR_RETURN(ocl::Buffer wb, ocl::Buffer::wrap(*rt, tb.vectors.size() * 4, const_cast<float*>(tb.vectors.data()), in));
  BTFC_ASSIGN_OR_RETURN(ocl::Buffer tx, ocl::Buffer::create(*rt, b.texels.size() * 4, b.texels.data(), in));
  BTFC_ASSIGN_OR_RETURN(ocl::Buffer co, ocl::Buffer::create(*rt, b.cand_off.size() * 4, b.cand_off.data(), in));
  BTFC_ASSIGN_OR_RETURN(ocl::Buffer ca, ocl::Buffer::create(*rt, pairs * 4, b.cand.data(), in));
  BTFC_ASSIGN_OR_RETURN(ocl::Buffer pb, ocl::Buffer::wrap(*rt, pairs * 8 * stride * 4, P, ocl::Access::read_write));
  for (size_t r0 = 0; r0 < d; r0 += size_t(k_chunk)) {
    const int32_t rc = int32_t(std::min<size_t>(size_t(k_chunk), d - r0)), first = r0 == 0;
    BTFC_RETURN_IF_ERROR(kp.args(xb, int32_t(d), tx, co, ca, wb, int32_t(tb.V), int32_t(r0), rc, int32_t(groups), first, pb));
    // One work-item per work-group: groups differ in their candidate counts, and PoCL's own
    // choice (a large divisor of the global size) left one of the 2 cores idle for much of a
    // launch (assignment 1.3-1.6x slower at 128^2 texels).
    const size_t global = groups, local = 1;
    BTFC_RETURN_IF_ERROR(kp.launch(1, &global, &local, "lpca_project"));
  }
  return pb.sync_to_host(pairs * 8 * stride * 4);
}

Status project(const ProjectionTable& t, const GroupBatch& b, float* P) {
  if (ocl::use_opencl()) {
    // The kernel only writes P; on a failure the reference recomputes all of it.
    Status s = project_cl(t, b, P);
    if (s.ok() || !ocl::fall_back_after(s)) return s;
  }
  project_reference(t, b, P);
  return {};
}

void relight_reference(std::span<const uint32_t> cluster, const float* W, int c, const float* L, float* out) {
#pragma omp parallel for schedule(static)
  for (size_t t = 0; t < cluster.size(); ++t) {
    const size_t r0 = size_t(cluster[t]) * size_t(c + 1);
    for (int ch = 0; ch < 3; ++ch) {
      float s = L[r0 * 3 + size_t(ch)];
      for (int i = 0; i < c; ++i) s += W[t * size_t(c) + size_t(i)] * L[(r0 + 1 + size_t(i)) * 3 + size_t(ch)];
      out[t * 3 + size_t(ch)] = s;
    }
  }
}

Status relight_cl(std::span<const uint32_t> cluster, const float* W, int c, const float* L, size_t L_rows, float* out) {
  BTFC_ASSIGN_OR_RETURN(ocl::Runtime * rt, ocl::Runtime::get());
  BTFC_ASSIGN_OR_RETURN(ocl::Kernel k, rt->kernel("lpca", "lpca_relight"));
  const size_t n = cluster.size();
  if (n == 0) return {};
  const auto in = ocl::Access::read_only;
  BTFC_ASSIGN_OR_RETURN(ocl::Buffer cb, ocl::Buffer::wrap(*rt, n * 4, const_cast<uint32_t*>(cluster.data()), in));
  BTFC_ASSIGN_OR_RETURN(ocl::Buffer wb, ocl::Buffer::wrap(*rt, std::max<size_t>(1, n * size_t(c)) * 4, const_cast<float*>(W), in));
  BTFC_ASSIGN_OR_RETURN(ocl::Buffer lb, ocl::Buffer::create(*rt, L_rows * 3 * 4, L, in));
  BTFC_ASSIGN_OR_RETURN(ocl::Buffer ob, ocl::Buffer::wrap(*rt, n * 12, out, ocl::Access::write_only));
  BTFC_RETURN_IF_ERROR(k.args(cb, wb, int32_t(c), lb, int32_t(n), ob));
  const size_t local = 64, global = (n + local - 1) / local * local;
  BTFC_RETURN_IF_ERROR(k.launch(1, &global, &local, "lpca_relight"));
  return ob.sync_to_host(n * 12);
}

Status relight(std::span<const uint32_t> cluster, const float* W, int c, const float* L, size_t L_rows, float* out) {
  if (ocl::use_opencl()) {
    Status s = relight_cl(cluster, W, c, L, L_rows, out);
    if (s.ok() || !ocl::fall_back_after(s)) return s;
  }
  relight_reference(cluster, W, c, L, out);
  return {};
}

}  // namespace btfc::lpca_cl
