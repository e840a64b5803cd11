// fmf OpenCL host code and C++ references; see fmf_cl.h.
#include "codecs/fmf/fmf_cl.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstring>

#include "core/cl_runtime.h"

namespace btfc::fmf_cl {
namespace {

// The kernel's summation order: 8 lanes of partial sums, then a pairwise reduction and the tail.
// Written as multiply + add (not std::fma) so GCC vectorizes the lanes: a fair yardstick for
// the kernels' speed; fused or not, the results differ only by float rounding.
float dot(const float* a, const float* b, int C) {
  float acc[8] = {0, 0, 0, 0, 0, 0, 0, 0};
  int k = 0;
  for (; k + 8 <= C; k += 8)
    for (int j = 0; j < 8; ++j) acc[j] += a[k + j] * b[k + j];
  const float h0 = acc[0] + acc[4], h1 = acc[1] + acc[5], h2 = acc[2] + acc[6], h3 = acc[3] + acc[7];
  float s = (h0 + h1) + (h2 + h3);
  for (; k < C; ++k) s += a[k] * b[k];
  return s;
}

void undecorrelate(float ylog, float u, float v, float eps, float* rgb) {
  const float y = std::exp(ylog) - eps, s = y + eps;
  u *= s, v *= s;
  rgb[0] = y + 1.13983f * v;
  rgb[1] = y - 0.39465f * u - 0.5806f * v;
  rgb[2] = y + 2.03211f * u;
}

void value(const PackedFactors& f, int texel, int l, int v, float* rgb) {
  const int C = f.C;
  if (f.mode == BTFC_FMF_RGB) {
    const float* sx = f.SxV.data() + size_t(texel) * C;
    const float* u = f.U.data() + size_t(3 * (l + f.nL * v)) * C;
    for (int c = 0; c < 3; ++c) rgb[c] = dot(u + c * C, sx, C);
    return;
  }
  const size_t r = size_t(l + f.nL * v) * C, t = size_t(texel) * C;
  const size_t ub = size_t(f.rows_per_block) * C, sb = size_t(f.texels) * C;
  undecorrelate(dot(f.U.data() + r, f.SxV.data() + t, C), dot(f.U.data() + ub + r, f.SxV.data() + sb + t, C),
                dot(f.U.data() + 2 * ub + r, f.SxV.data() + 2 * sb + t, C), f.eps, rgb);
}

}  // namespace

void eval_measured_reference(const PackedFactors& f, std::span<const MeasuredQuery> q, float* out) {
#pragma omp parallel for schedule(static)
  for (size_t i = 0; i < q.size(); ++i) value(f, q[i].texel, q[i].light, q[i].view, out + 3 * i);
}

namespace {

// The rgb interpolation in the kernel's order: the 9 rows blended 8 components at a time and
// dotted with the texel's row as they go (fmf.cl, fmf_eval_interp).
void interp_rgb(const PackedFactors& f, const btfc_fmf_query& Q, float* out) {
  const int C = f.C;
  const float* s = f.SxV.data() + size_t(Q.texel) * C;
  const float* row[9];
  float w[9];
  int m = 0;
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) {
      const float wab = Q.wl[a] * Q.wv[b];
      if (wab == 0) continue;
      row[m] = f.U.data() + size_t(3 * (Q.light[a] + f.nL * Q.view[b])) * C;
      w[m++] = wab;
    }
  float acc[3][8] = {};
  int k = 0;
  for (; k + 8 <= C; k += 8)
    for (int c = 0; c < 3; ++c) {
      float u[8] = {};
      for (int j = 0; j < m; ++j)
        for (int l = 0; l < 8; ++l) u[l] += w[j] * row[j][c * C + k + l];
      for (int l = 0; l < 8; ++l) acc[c][l] += u[l] * s[k + l];
    }
  float r[3];
  for (int c = 0; c < 3; ++c) {
    const float* a = acc[c];
    r[c] = ((a[0] + a[4]) + (a[1] + a[5])) + ((a[2] + a[6]) + (a[3] + a[7]));
  }
  for (; k < C; ++k)
    for (int c = 0; c < 3; ++c) {
      float u = 0;
      for (int j = 0; j < m; ++j) u += w[j] * row[j][c * C + k];
      r[c] += u * s[k];
    }
  for (int c = 0; c < 3; ++c) out[c] = r[c];
}

bool same_pair(const btfc_fmf_query& a, const btfc_fmf_query& b) {
  return std::memcmp(a.light, b.light, sizeof(a) - offsetof(btfc_fmf_query, light)) == 0;
}

// Calls pair(first, n) for each run of >= k_min_pair_run consecutive queries sharing a direction
// pair and interp(first, n) for the stretches between them.
template <class Interp, class Pair>
Status for_each_run(std::span<const btfc_fmf_query> q, Interp&& interp, Pair&& pair) {
  size_t loose = 0, i = 0;  // [loose, i) not yet evaluated, no long run inside
  while (i < q.size()) {
    size_t j = i + 1;
    while (j < q.size() && same_pair(q[j], q[i])) ++j;
    if (j - i >= k_min_pair_run) {
      if (i > loose) BTFC_RETURN_IF_ERROR(interp(loose, i - loose));
      BTFC_RETURN_IF_ERROR(pair(i, j - i));
      loose = j;
    }
    i = j;
  }
  if (q.size() > loose) BTFC_RETURN_IF_ERROR(interp(loose, q.size() - loose));
  return {};
}

std::vector<int> texels_of(std::span<const btfc_fmf_query> q) {
  std::vector<int> t(q.size());
  for (size_t i = 0; i < q.size(); ++i) t[i] = q[i].texel;
  return t;
}

}  // namespace

void blend_pair(const PackedFactors& f, const btfc_fmf_query& Q, float* Ub) {
  const size_t n = size_t(3) * f.C;
  std::fill(Ub, Ub + n, 0.0f);
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) {
      const float w = Q.wl[a] * Q.wv[b];
      if (w == 0) continue;
      const float* row = f.U.data() + size_t(3 * (Q.light[a] + f.nL * Q.view[b])) * f.C;
      for (size_t k = 0; k < n; ++k) Ub[k] += w * row[k];
    }
}

void eval_pair_reference(const PackedFactors& f, const btfc_fmf_query& pair, std::span<const int> texels, float* out) {
  if (f.mode != BTFC_FMF_RGB) {
    std::vector<btfc_fmf_query> q(texels.size(), pair);
    for (size_t i = 0; i < q.size(); ++i) q[i].texel = texels[i];
    eval_interp_reference(f, q, out);
    return;
  }
  const int C = f.C;
  std::vector<float> Ub(size_t(3) * C);
  blend_pair(f, pair, Ub.data());
#pragma omp parallel for schedule(static)
  for (size_t i = 0; i < texels.size(); ++i) {
    const float* s = f.SxV.data() + size_t(texels[i]) * C;
    for (int c = 0; c < 3; ++c) out[3 * i + c] = dot(Ub.data() + c * C, s, C);
  }
}

void eval_batch_reference(const PackedFactors& f, std::span<const btfc_fmf_query> q, float* out) {
  (void)for_each_run(
      q, [&](size_t first, size_t n) { eval_interp_reference(f, q.subspan(first, n), out + 3 * first); return Status(); },
      [&](size_t first, size_t n) {
        eval_pair_reference(f, q[first], texels_of(q.subspan(first, n)), out + 3 * first);
        return Status();
      });
}

void eval_interp_reference(const PackedFactors& f, std::span<const btfc_fmf_query> q, float* out) {
  if (f.mode == BTFC_FMF_RGB) {
#pragma omp parallel for schedule(static)
    for (size_t i = 0; i < q.size(); ++i) interp_rgb(f, q[i], out + 3 * i);
    return;
  }
#pragma omp parallel for schedule(static)
  for (size_t i = 0; i < q.size(); ++i) {
    float acc[3] = {0, 0, 0}, v[3];
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) {
        const float w = q[i].wl[a] * q[i].wv[b];
        if (w == 0) continue;
        value(f, q[i].texel, q[i].light[a], q[i].view[b], v);
        for (int c = 0; c < 3; ++c) acc[c] += w * v[c];
      }
    for (int c = 0; c < 3; ++c) out[3 * i + c] = acc[c];
  }
}

void decode_reference(const PackedFactors& f, std::span<const int> texels, std::span<const int> lights,
                      std::span<const int> views, float* out) {
  const size_t nl = lights.size(), nv = views.size(), rows = 3 * nl * nv;
#pragma omp parallel for schedule(static)
  for (size_t i = 0; i < texels.size(); ++i)
    for (size_t v = 0; v < nv; ++v)
      for (size_t l = 0; l < nl; ++l) value(f, texels[i], lights[l], views[v], out + i * rows + 3 * (l + nl * v));
}

// ---------------------------------------------------------------------------------------------

struct DeviceFactors::Impl {
  PackedFactors shape;  // host copy: decode gathers the selected rows / texels from it
  ocl::Buffer U, SxV;
};

DeviceFactors::~DeviceFactors() = default;

Result<std::shared_ptr<DeviceFactors>> DeviceFactors::upload(const PackedFactors& f) {
  BTFC_ASSIGN_OR_RETURN(ocl::Runtime * rt, ocl::Runtime::get());
  auto d = std::shared_ptr<DeviceFactors>(new DeviceFactors());
  d->m = std::make_unique<Impl>();
  d->m->shape = f;
  BTFC_ASSIGN_OR_RETURN(d->m->U, ocl::Buffer::create(*rt, f.U.size() * 4, f.U.data(), ocl::Access::read_only));
  BTFC_ASSIGN_OR_RETURN(d->m->SxV, ocl::Buffer::create(*rt, f.SxV.size() * 4, f.SxV.data(), ocl::Access::read_only));
  return d;
}

namespace {

// Block b's own component count (PackedFactors::block_C; C where it is not given).
int32_t own_C(const PackedFactors& s, int b) {
  return int32_t(size_t(b) < s.block_C.size() ? std::clamp(s.block_C[size_t(b)], 0, s.C) : s.C);
}

// Queries go in slices so each slice's buffers stay far below the device's allocation limit.
constexpr size_t k_slice = size_t(1) << 22;

template <class Q>
Status run_eval(const DeviceFactors::Impl& m, const char* kernel_name, std::span<const Q> q, float* out) {
  BTFC_ASSIGN_OR_RETURN(ocl::Runtime * rt, ocl::Runtime::get());
  BTFC_ASSIGN_OR_RETURN(ocl::Kernel k, rt->kernel("fmf", kernel_name));
  const PackedFactors& s = m.shape;
  const int32_t Cy = own_C(s, 0), Cu = own_C(s, 1), Cv = own_C(s, 2);
  for (size_t first = 0; first < q.size(); first += k_slice) {
    const size_t n = std::min(k_slice, q.size() - first);
    BTFC_ASSIGN_OR_RETURN(ocl::Buffer qb, ocl::Buffer::wrap(*rt, n * sizeof(Q), const_cast<Q*>(q.data() + first), ocl::Access::read_only));
    BTFC_ASSIGN_OR_RETURN(ocl::Buffer ob, ocl::Buffer::wrap(*rt, n * 12, out + 3 * first, ocl::Access::write_only));
    BTFC_RETURN_IF_ERROR(k.args(m.U, m.SxV, s.C, s.nL, s.rows_per_block, s.texels, s.mode, s.eps, Cy, Cu, Cv, qb, int32_t(n), ob));
    const size_t local = 64, global = (n + local - 1) / local * local;
    BTFC_RETURN_IF_ERROR(k.launch(1, &global, &local, kernel_name));
    BTFC_RETURN_IF_ERROR(ob.sync_to_host(n * 12));
  }
  return {};
}

}  // namespace

Status DeviceFactors::eval_measured(std::span<const MeasuredQuery> q, float* out) const {
  return run_eval(*m, "fmf_eval_measured", q, out);
}

Status DeviceFactors::eval_interp(std::span<const btfc_fmf_query> q, float* out) const {
  return run_eval(*m, "fmf_eval_interp", q, out);
}

Status DeviceFactors::eval_pair(const btfc_fmf_query& pair, std::span<const int> texels, float* out) const {
  const PackedFactors& s = m->shape;
  if (s.mode != BTFC_FMF_RGB) {
    std::vector<btfc_fmf_query> q(texels.size(), pair);
    for (size_t i = 0; i < q.size(); ++i) q[i].texel = texels[i];
    return eval_interp(q, out);
  }
  BTFC_ASSIGN_OR_RETURN(ocl::Runtime * rt, ocl::Runtime::get());
  BTFC_ASSIGN_OR_RETURN(ocl::Kernel k, rt->kernel("fmf", "fmf_eval_pair_rgb"));
  std::vector<float> Ub(size_t(3) * s.C);
  blend_pair(s, pair, Ub.data());
  BTFC_ASSIGN_OR_RETURN(ocl::Buffer ub, ocl::Buffer::create(*rt, Ub.size() * 4, Ub.data(), ocl::Access::read_only));
  for (size_t first = 0; first < texels.size(); first += k_slice) {
    const size_t n = std::min(k_slice, texels.size() - first);
    BTFC_ASSIGN_OR_RETURN(ocl::Buffer tb, ocl::Buffer::wrap(*rt, n * 4, const_cast<int*>(texels.data() + first), ocl::Access::read_only));
    BTFC_ASSIGN_OR_RETURN(ocl::Buffer ob, ocl::Buffer::wrap(*rt, n * 12, out + 3 * first, ocl::Access::write_only));
    BTFC_RETURN_IF_ERROR(k.args(ub, m->SxV, s.C, tb, int32_t(n), ob));
    const size_t local = 64, global = (n + local - 1) / local * local;
    BTFC_RETURN_IF_ERROR(k.launch(1, &global, &local, "fmf_eval_pair_rgb"));
    BTFC_RETURN_IF_ERROR(ob.sync_to_host(n * 12));
  }
  return {};
}

Status DeviceFactors::eval_batch(std::span<const btfc_fmf_query> q, float* out) const {
  return for_each_run(
      q, [&](size_t first, size_t n) { return eval_interp(q.subspan(first, n), out + 3 * first); },
      [&](size_t first, size_t n) { return eval_pair(q[first], texels_of(q.subspan(first, n)), out + 3 * first); });
}

Status DeviceFactors::decode(std::span<const int> texels, std::span<const int> lights, std::span<const int> views,
                             float* out) const {
  BTFC_ASSIGN_OR_RETURN(ocl::Runtime * rt, ocl::Runtime::get());
  const PackedFactors& s = m->shape;
  const bool rgb = s.mode == BTFC_FMF_RGB;
  BTFC_ASSIGN_OR_RETURN(ocl::Kernel k, rt->kernel("fmf", rgb ? "fmf_decode_rgb" : "fmf_decode_dfmf"));
  const size_t nl = lights.size(), nv = views.size(), dirs = nl * nv, rows = 3 * dirs, C = size_t(s.C);
  // The selected U rows, transposed per block (kernel reads 16 consecutive rows as a float16).
  const size_t cols = rgb ? rows : dirs;  // columns of Ut per block
  std::vector<float> Ut(size_t(s.blocks) * C * cols);
  {
    const std::vector<float>& U = s.U;
    for (int b = 0; b < s.blocks; ++b)
      for (size_t v = 0; v < nv; ++v)
        for (size_t l = 0; l < nl; ++l)
          for (size_t c = 0; c < (rgb ? 3u : 1u); ++c) {
            const size_t src_row = rgb ? c + 3 * (size_t(lights[l]) + size_t(s.nL) * views[v]) : size_t(lights[l]) + size_t(s.nL) * views[v];
            const size_t dst_col = rgb ? c + 3 * (l + nl * v) : l + nl * v;
            for (size_t kk = 0; kk < C; ++kk)
              Ut[(size_t(b) * C + kk) * cols + dst_col] = U[(size_t(b) * s.rows_per_block + src_row) * C + kk];
          }
  }
  BTFC_ASSIGN_OR_RETURN(ocl::Buffer utb, ocl::Buffer::create(*rt, Ut.size() * 4, Ut.data(), ocl::Access::read_only));
  // Texel blocks keep the output buffer near 128 MiB.
  const size_t per_block = std::max<size_t>(1, (size_t(128) << 20) / (rows * 4));
  std::vector<float> SX;
  const std::vector<float>& SXall = s.SxV;
  for (size_t first = 0; first < texels.size(); first += per_block) {
    const size_t n = std::min(per_block, texels.size() - first);
    SX.assign(size_t(s.blocks) * n * C, 0.0f);
    for (int b = 0; b < s.blocks; ++b)
      for (size_t i = 0; i < n; ++i)
        std::copy_n(SXall.data() + (size_t(b) * s.texels + size_t(texels[first + i])) * C, C, SX.data() + (size_t(b) * n + i) * C);
    BTFC_ASSIGN_OR_RETURN(ocl::Buffer sxb, ocl::Buffer::create(*rt, SX.size() * 4, SX.data(), ocl::Access::read_only));
    BTFC_ASSIGN_OR_RETURN(ocl::Buffer ob, ocl::Buffer::wrap(*rt, n * rows * 4, out + first * rows, ocl::Access::write_only));
    if (rgb) {
      BTFC_RETURN_IF_ERROR(k.args(utb, sxb, int32_t(C), int32_t(cols), int32_t(n), ob));
    } else {
      BTFC_RETURN_IF_ERROR(k.args(utb, sxb, int32_t(C), own_C(s, 0), own_C(s, 1), own_C(s, 2), int32_t(cols), int32_t(n), s.eps, ob));
    }
    // Each work-item does 16 rows (rgb) or directions (dfmf) x 4 texels.
    const size_t global[2] = {(cols + 15) / 16, (n + 3) / 4};
    BTFC_RETURN_IF_ERROR(k.launch(2, global, nullptr, "fmf_decode"));
    BTFC_RETURN_IF_ERROR(ob.sync_to_host(n * rows * 4));
  }
  return {};
}

}  // namespace btfc::fmf_cl
