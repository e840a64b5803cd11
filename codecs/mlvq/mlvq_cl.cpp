// mlvq OpenCL host code and C++ references; see mlvq_cl.h.
#include "codecs/mlvq/mlvq_cl.h"

#include <algorithm>
#include <cmath>

#include "codecs/mlvq/mlvq_internal.h"
#include "core/cl_runtime.h"

namespace btfc::mlvq {

namespace {

// The kernels' float arithmetic (mlvq.cl mlvq_ssim / mlvq_dot), in the same order.
float ssim_f(float n, float sx, float sxx, float se, float see, float sxe, float L, bool scaled, float* scale) {
  float s = 1.0f;
  if (scaled) s = see > 0.0f ? std::max(0.0f, sxe / see) : 0.0f;
  *scale = s;
  const float mx = sx / n, me = se / n, my = s * me;
  const float vx = std::max(0.0f, sxx / n - mx * mx), vy = std::max(0.0f, s * s * (see / n - me * me));
  const float cxy = s * (sxe / n - mx * me);
  const float c1 = (0.01f * L) * (0.01f * L), c2 = (0.03f * L) * (0.03f * L);
  if (c1 == 0.0f && c2 == 0.0f) return 1.0f;
  return ((2.0f * mx * my + c1) * (2.0f * cxy + c2)) / ((mx * mx + my * my + c1) * (vx + vy + c2));
}

float dot_f(const float* a, const float* b, int n) {
  float acc[8] = {0, 0, 0, 0, 0, 0, 0, 0};
  int k = 0;
  for (; k + 8 <= n; k += 8)
    for (int j = 0; j < 8; ++j) acc[j] = std::fma(a[k + j], b[k + j], acc[j]);
  const float h0 = acc[0] + acc[4], h1 = acc[1] + acc[5], h2 = acc[2] + acc[6], h3 = acc[3] + acc[7];
  float s = (h0 + h1) + (h2 + h3);
  for (; k < n; ++k) s = std::fma(a[k], b[k], s);
  return s;
}

}  // namespace

void ssim_search_reference(const SearchProblem& p, SearchResult& r) {
  r.idx.assign(size_t(p.B), -1);
  r.sim.assign(size_t(p.B), -3.f);
  r.scale.assign(size_t(p.B), 1.f);
#pragma omp parallel for schedule(static)
  for (int i = 0; i < p.B; ++i) {
    const double* m = p.xm + 5 * i;
    const float m0 = float(m[0]), m1 = float(m[1]), m2 = float(m[2]), m3 = float(m[3]), m4 = float(m[4]);
    float bs = -3, bsc = 1, unused;
    int bj = -1;
    for (int j = 0; j < p.K; ++j) {
      const double* e = p.em + 4 * j;
      float s = 2, sc = 1;
      if (p.dl > 0)
        s = ssim_f(float(p.dl), m0, m1, float(e[0]), float(e[1]), dot_f(p.Xl + size_t(i) * p.dl, p.El + size_t(j) * p.dl, p.dl), m2, true, &sc) - p.tl;
      if (p.dc > 0 && s > bs)
        s = std::min(s, ssim_f(float(p.dc), m3, m4, float(e[2]), float(e[3]), dot_f(p.Xc + size_t(i) * p.dc, p.Ec + size_t(j) * p.dc, p.dc), 1.0f,
                               false, &unused) - p.tc);
      if (s > bs) bs = s, bj = j, bsc = sc;
    }
    r.idx[size_t(i)] = bj, r.sim[size_t(i)] = bs, r.scale[size_t(i)] = bsc;
  }
}

Status ssim_search_cl(const SearchProblem& p, SearchResult& r) {
  BTFC_ASSIGN_OR_RETURN(ocl::Runtime * rt, ocl::Runtime::get());
  BTFC_ASSIGN_OR_RETURN(ocl::Kernel k, rt->kernel("mlvq", "mlvq_ssim_search"));
  std::vector<float> xm(size_t(5 * p.B)), em(size_t(4 * p.K));
  for (size_t i = 0; i < xm.size(); ++i) xm[i] = float(p.xm[i]);
  for (size_t i = 0; i < em.size(); ++i) em[i] = float(p.em[i]);
  const float dummy = 0;
  auto buf = [&](const float* h, size_t n) { return ocl::Buffer::create(*rt, std::max<size_t>(n, 1) * 4, n ? h : &dummy, ocl::Access::read_only); };
  BTFC_ASSIGN_OR_RETURN(ocl::Buffer bxl, buf(p.Xl, size_t(p.B) * p.dl));
  BTFC_ASSIGN_OR_RETURN(ocl::Buffer bxc, buf(p.Xc, size_t(p.B) * p.dc));
  BTFC_ASSIGN_OR_RETURN(ocl::Buffer bel, buf(p.El, size_t(p.K) * p.dl));
  BTFC_ASSIGN_OR_RETURN(ocl::Buffer bec, buf(p.Ec, size_t(p.K) * p.dc));
  BTFC_ASSIGN_OR_RETURN(ocl::Buffer bxm, buf(xm.data(), xm.size()));
  BTFC_ASSIGN_OR_RETURN(ocl::Buffer bem, buf(em.data(), em.size()));
  r.idx.assign(size_t(p.B), -1);
  r.sim.assign(size_t(p.B), -3.f);
  r.scale.assign(size_t(p.B), 1.f);
  BTFC_ASSIGN_OR_RETURN(ocl::Buffer bi, ocl::Buffer::wrap(*rt, size_t(p.B) * 4, r.idx.data(), ocl::Access::write_only));
  BTFC_ASSIGN_OR_RETURN(ocl::Buffer bs, ocl::Buffer::wrap(*rt, size_t(p.B) * 4, r.sim.data(), ocl::Access::write_only));
  BTFC_ASSIGN_OR_RETURN(ocl::Buffer bc, ocl::Buffer::wrap(*rt, size_t(p.B) * 4, r.scale.data(), ocl::Access::write_only));
  BTFC_RETURN_IF_ERROR(k.args(bxl, bxc, bel, bec, bxm, bem, int32_t(p.B), int32_t(p.K), int32_t(p.dl), int32_t(p.dc), p.tl, p.tc, bi, bs, bc));
  const size_t global = size_t(p.B);
  BTFC_RETURN_IF_ERROR(k.launch(1, &global, nullptr, "mlvq_ssim_search"));
  BTFC_RETURN_IF_ERROR(bi.sync_to_host(size_t(p.B) * 4));
  BTFC_RETURN_IF_ERROR(bs.sync_to_host(size_t(p.B) * 4));
  BTFC_RETURN_IF_ERROR(bc.sync_to_host(size_t(p.B) * 4));
  return {};
}

void rgb_to_lrg_reference(std::span<const float> rgb, float* lrg) {
  const size_t n = rgb.size() / 3;
#pragma omp parallel for schedule(static)
  for (size_t i = 0; i < n; ++i) rgb_to_lrg(rgb.data() + 3 * i, lrg + 3 * i);
}

Status rgb_to_lrg_cl(std::span<const float> rgb, float* lrg) {
  BTFC_ASSIGN_OR_RETURN(ocl::Runtime * rt, ocl::Runtime::get());
  BTFC_ASSIGN_OR_RETURN(ocl::Kernel k, rt->kernel("mlvq", "mlvq_rgb_to_lrg"));
  const size_t n = rgb.size() / 3;
  if (n == 0) return {};
  BTFC_ASSIGN_OR_RETURN(ocl::Buffer bi, ocl::Buffer::create(*rt, n * 12, rgb.data(), ocl::Access::read_only));
  BTFC_ASSIGN_OR_RETURN(ocl::Buffer bo, ocl::Buffer::wrap(*rt, n * 12, lrg, ocl::Access::write_only));
  BTFC_RETURN_IF_ERROR(k.args(bi, int32_t(n), bo));
  BTFC_RETURN_IF_ERROR(k.launch(1, &n, nullptr, "mlvq_rgb_to_lrg"));
  return bo.sync_to_host(n * 12);
}

FlatModel flatten(const Hierarchy& h) {
  FlatModel f;
  f.meta.assign(21, 0);
  f.meta[0] = h.scheme;
  for (int k = 1; k <= 4; ++k) f.meta[size_t(k)] = h.grid.n(k);
  auto put = [&](const Book& b, bool scaled) {
    const int off = int(f.idx.size());
    f.idx.insert(f.idx.end(), b.child.begin(), b.child.end());
    if (scaled) f.val.insert(f.val.end(), b.scale.begin(), b.scale.end());
    else f.val.insert(f.val.end(), b.child.size(), 1.f);
    return off;
  };
  for (int k = 2; k <= 4; ++k) {
    f.meta[size_t(5 + k - 1)] = put(h.rgb[k], true);
    f.meta[size_t(9 + k - 1)] = put(h.lum[k], true);
    f.meta[size_t(13 + k - 1)] = put(h.chroma[k], false);
  }
  f.meta[17] = int(f.idx.size());
  for (size_t i = 0; i < h.merge_lum.size(); ++i) f.idx.push_back(h.merge_lum[i]), f.idx.push_back(h.merge_chroma[i]);
  f.val.resize(f.idx.size(), 0.f);
  f.meta[18] = int(f.val.size());
  f.val.insert(f.val.end(), h.lum[1].values.begin(), h.lum[1].values.end());
  f.meta[19] = int(f.val.size());
  f.val.insert(f.val.end(), h.chroma[1].values.begin(), h.chroma[1].values.end());
  f.idx.resize(f.val.size(), 0);
  f.meta[20] = int(f.idx.size());
  f.idx.insert(f.idx.end(), h.texel_idx.begin(), h.texel_idx.end());
  f.val.insert(f.val.end(), h.texel_scale.begin(), h.texel_scale.end());
  return f;
}

namespace {

void node_flat(const FlatModel& f, int texel, const int* coord, float rgb[3]) {
  const int* meta = f.meta.data();
  const int s = meta[0];
  uint32_t e = f.idx[size_t(meta[20] + texel)];
  float sc = f.val[size_t(meta[20] + texel)];
  for (int k = 4; k > s; --k) {
    const size_t o = size_t(meta[5 + k - 1]) + size_t(e) * size_t(meta[k]) + size_t(coord[k]);
    sc *= f.val[o];
    e = f.idx[o];
  }
  uint32_t li = f.idx[size_t(meta[17]) + 2 * size_t(e)], ci = f.idx[size_t(meta[17]) + 2 * size_t(e) + 1];
  for (int k = s; k > 1; --k) {
    const size_t o = size_t(meta[9 + k - 1]) + size_t(li) * size_t(meta[k]) + size_t(coord[k]);
    sc *= f.val[o];
    li = f.idx[o];
    ci = f.idx[size_t(meta[13 + k - 1]) + size_t(ci) * size_t(meta[k]) + size_t(coord[k])];
  }
  const size_t nb = size_t(meta[1]);
  const float L = sc * f.val[size_t(meta[18]) + size_t(li) * nb + size_t(coord[1])];
  const size_t co = size_t(meta[19]) + 2 * (size_t(ci) * nb + size_t(coord[1]));
  const float lrg[3] = {L, f.val[co], f.val[co + 1]};
  lrg_to_rgb(lrg, rgb);
}

}  // namespace

void eval_flat_reference(const FlatModel& f, std::span<const int> texel, std::span<const float> coord, float* out) {
  Grid g;
  g.nbeta = f.meta[1], g.nalpha = f.meta[2], g.ntheta = f.meta[3], g.nphi = f.meta[4];
#pragma omp parallel for schedule(static)
  for (size_t q = 0; q < texel.size(); ++q) {
    const GridCoord c{coord[4 * q], coord[4 * q + 1], coord[4 * q + 2], coord[4 * q + 3]};
    const Stencil s = stencil(g, c);
    float acc[3] = {0, 0, 0}, v[3];
    for (int m = 0; m < 16; ++m) {
      const float w = s.w[0][m & 1] * s.w[1][(m >> 1) & 1] * s.w[2][(m >> 2) & 1] * s.w[3][(m >> 3) & 1];
      if (w == 0) continue;
      const int cd[5] = {0, s.i[0][m & 1], s.i[1][(m >> 1) & 1], s.i[2][(m >> 2) & 1], s.i[3][(m >> 3) & 1]};
      node_flat(f, texel[q], cd, v);
      for (int c2 = 0; c2 < 3; ++c2) acc[c2] += w * v[c2];
    }
    std::copy(acc, acc + 3, out + 3 * q);
  }
}

struct DeviceModel::Impl {
  ocl::Buffer meta, idx, val;
};

DeviceModel::~DeviceModel() = default;

Result<std::shared_ptr<DeviceModel>> DeviceModel::upload(const FlatModel& f) {
  BTFC_ASSIGN_OR_RETURN(ocl::Runtime * rt, ocl::Runtime::get());
  auto d = std::shared_ptr<DeviceModel>(new DeviceModel());
  d->m = std::make_unique<Impl>();
  BTFC_ASSIGN_OR_RETURN(d->m->meta, ocl::Buffer::create(*rt, f.meta.size() * 4, f.meta.data(), ocl::Access::read_only));
  BTFC_ASSIGN_OR_RETURN(d->m->idx, ocl::Buffer::create(*rt, f.idx.size() * 4, f.idx.data(), ocl::Access::read_only));
  BTFC_ASSIGN_OR_RETURN(d->m->val, ocl::Buffer::create(*rt, f.val.size() * 4, f.val.data(), ocl::Access::read_only));
  return d;
}

Status DeviceModel::eval(std::span<const int> texel, std::span<const float> coord, float* out) const {
  BTFC_ASSIGN_OR_RETURN(ocl::Runtime * rt, ocl::Runtime::get());
  BTFC_ASSIGN_OR_RETURN(ocl::Kernel k, rt->kernel("mlvq", "mlvq_eval"));
  constexpr size_t slice = size_t(1) << 22;
  for (size_t first = 0; first < texel.size(); first += slice) {
    const size_t n = std::min(slice, texel.size() - first);
    BTFC_ASSIGN_OR_RETURN(ocl::Buffer bt, ocl::Buffer::wrap(*rt, n * 4, const_cast<int*>(texel.data() + first), ocl::Access::read_only));
    BTFC_ASSIGN_OR_RETURN(ocl::Buffer bc, ocl::Buffer::wrap(*rt, n * 16, const_cast<float*>(coord.data() + 4 * first), ocl::Access::read_only));
    BTFC_ASSIGN_OR_RETURN(ocl::Buffer bo, ocl::Buffer::wrap(*rt, n * 12, out + 3 * first, ocl::Access::write_only));
    BTFC_RETURN_IF_ERROR(k.args(m->meta, m->idx, m->val, bt, bc, int32_t(n), bo));
    const size_t local = 64, global = (n + local - 1) / local * local;
    BTFC_RETURN_IF_ERROR(k.launch(1, &global, &local, "mlvq_eval"));
    BTFC_RETURN_IF_ERROR(bo.sync_to_host(n * 12));
  }
  return {};
}

}  // namespace btfc::mlvq
