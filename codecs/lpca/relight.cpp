// Environment relighting and PRT for lpca models (seed 002 sections 4-5). Environment maps are
// read by formats/exr/envmap.h: this file sees only pixels.
// See lpca.h for the frames, the lat-long layout and the PRT quantization.
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <exception>

#include "codecs/lpca/lpca.h"
#include "codecs/lpca/lpca_cl.h"
#include "codecs/lpca/lpca_model.h"

namespace btfc {
namespace {

using lpca::LpcaModel;
constexpr int k_prt_res = 16;

Result<const LpcaModel*> as_lpca(const Model& m) {
  const auto* p = dynamic_cast<const LpcaModel*>(&m);
  if (!p) return invalid_argument("relighting needs an lpca model, got '" + m.spec() + "'");
  return p;
}

Status check_env(const EnvironmentSH& env) {
  if (env.order < 1 || env.order > sh::k_max_order || env.coeffs.size() != size_t(3) * size_t(env.order) * size_t(env.order))
    return invalid_argument("environment: order " + std::to_string(env.order) + " with " + std::to_string(env.coeffs.size()) +
                            " coefficients (need order in [1, 16] and 3 x order^2 coefficients)");
  return {};
}

// lambda[row][view][channel] = <e^v_row, a> over the first min(env, model) orders' coefficients,
// with the environment already in the sample frame.
std::vector<float> dot_products(const LpcaModel& m, const EnvironmentSH& env_s) {
  const int nc = m.desc().channels, nv = int(m.desc().num_views());
  const int n2m = sh::num_coeffs(m.config().sh_order), n2e = sh::num_coeffs(env_s.order);
  const int n2 = std::min(n2m, n2e);
  const size_t rows = size_t(m.table().rows());
  std::vector<float> lambda(rows * size_t(nv) * size_t(nc));
  const std::vector<float>& esh = m.eigen_sh();
#pragma omp parallel for schedule(static)
  for (size_t r = 0; r < rows; ++r)
    for (int v = 0; v < nv; ++v)
      for (int ch = 0; ch < nc; ++ch) {
        const size_t idx = (r * size_t(nv) + size_t(v)) * size_t(nc) + size_t(ch);
        const float* e = esh.data() + idx * size_t(n2m);
        const double* a = env_s.coeffs.data() + size_t(std::min(ch, 2)) * size_t(n2e);
        double s = 0;
        for (int j = 0; j < n2; ++j) s += double(e[j]) * a[j];
        lambda[idx] = float(s);
      }
  return lambda;
}

EnvironmentSH to_sample_frame(const EnvironmentSH& env_w, const RelightOptions& opt) {
  // L_s(d) = L_w(R d): the function rotated by R^T.
  return rotate_environment(env_w, opt.sample_to_world.transpose());
}

}  // namespace

Result<std::vector<float>> relight(const Model& model, const EnvironmentSH& env, const Vec3& view_dir, int& w, int& h,
                                   const RelightOptions& opt) {
  BTFC_ASSIGN_OR_RETURN(const LpcaModel* m, as_lpca(model));
  BTFC_RETURN_IF_ERROR(check_env(env));
  const double vw_in[3] = {view_dir.x, view_dir.y, view_dir.z};
  double vs[3];
  opt.sample_to_world.transpose().apply(vw_in, vs);
  const double len = std::sqrt(vs[0] * vs[0] + vs[1] * vs[1] + vs[2] * vs[2]);
  if (!(len > 0) || vs[2] / len <= 1e-6) return invalid_argument("relight: the view direction is at or below the sample's horizon");
  const Vec3 v{float(vs[0] / len), float(vs[1] / len), float(vs[2] / len)};
  const std::vector<float> lambda = dot_products(*m, to_sample_frame(env, opt));
  const BtfDesc& d = m->desc();
  const int nc = d.channels, nv = int(d.num_views()), c = m->components();
  const DirWeights vwts = m->view_interp().weights(v);
  const size_t rows = size_t(m->table().rows());
  std::vector<float> L(rows * 3, 0.f);  // per table row: lambda blended over the view triangle
  for (size_t r = 0; r < rows; ++r)
    for (int ch = 0; ch < 3; ++ch)
      for (int t = 0; t < 3; ++t)
        L[r * 3 + size_t(ch)] += vwts.weight[size_t(t)] *
                                 lambda[(r * size_t(nv) + size_t(vwts.index[size_t(t)])) * size_t(nc) + size_t(std::min(ch, nc - 1))];
  w = d.width, h = d.height;
  const size_t n = d.num_texels();
  std::vector<float> out(n * 3);
  // Per texel: the dot product of its reconstructed SH coefficients with the lighting, i.e.
  // L[r0] + sum_i w_i L[r0 + i] (lpca_cl.h: OpenCL kernel or its C++ reference).
  BTFC_RETURN_IF_ERROR(lpca_cl::relight(m->cluster_of(), m->weights().data(), c, L.data(), rows, out.data()));
  return out;
}

Result<std::vector<Tensor>> prt_tensors(const Model& model, const EnvironmentSH& env, const RelightOptions& opt) {
  BTFC_ASSIGN_OR_RETURN(const LpcaModel* m, as_lpca(model));
  BTFC_RETURN_IF_ERROR(check_env(env));
  const std::vector<float> lambda = dot_products(*m, to_sample_frame(env, opt));
  const BtfDesc& d = m->desc();
  const int nc = d.channels, nv = int(d.num_views()), c = m->components(), K = m->clusters();
  // View weights of each parabolic map texel.
  std::vector<DirWeights> pix(size_t(k_prt_res) * k_prt_res);
  for (int j = 0; j < k_prt_res; ++j)
    for (int i = 0; i < k_prt_res; ++i) {
      double px = (i + 0.5) / (k_prt_res / 2) - 1, py = (j + 0.5) / (k_prt_res / 2) - 1, r2 = px * px + py * py;
      if (r2 > 1) px /= std::sqrt(r2), py /= std::sqrt(r2), r2 = 1;  // outside the disc: the horizon
      const Vec3 dir{float(2 * px / (1 + r2)), float(2 * py / (1 + r2)), float((1 - r2) / (1 + r2))};
      pix[size_t(j) * k_prt_res + size_t(i)] = m->view_interp().weights(dir);
    }
  const size_t rows = size_t(K) * size_t(c + 1), per_row = size_t(k_prt_res) * k_prt_res * size_t(nc);
  std::vector<float> maps(rows * per_row);
  float scale[2] = {0, 0};
  for (size_t r = 0; r < rows; ++r)
    for (size_t p = 0; p < pix.size(); ++p)
      for (int ch = 0; ch < nc; ++ch) {
        float s = 0;
        for (int t = 0; t < 3; ++t)
          s += pix[p].weight[size_t(t)] * lambda[(r * size_t(nv) + size_t(pix[p].index[size_t(t)])) * size_t(nc) + size_t(ch)];
        maps[r * per_row + p * size_t(nc) + size_t(ch)] = s;
        float& sc = scale[r % size_t(c + 1) == 0 ? 0 : 1];
        sc = std::max(sc, std::abs(s));
      }
  for (float& s : scale)
    if (!(s > 0) || !std::isfinite(s)) s = 1;
  Tensor q;
  q.name = "prt";
  q.dtype = DType::u8;
  q.shape = {uint64_t(K), uint64_t(c + 1), uint64_t(k_prt_res), uint64_t(k_prt_res), uint64_t(nc)};
  q.bytes.resize(maps.size());
  for (size_t i = 0; i < maps.size(); ++i) {
    const float s = scale[(i / per_row) % size_t(c + 1) == 0 ? 0 : 1];
    q.bytes[i] = uint8_t(std::clamp(std::lround((maps[i] / s + 1) * 127.5f), 0L, 255L));
  }
  std::vector<Tensor> out;
  out.push_back(std::move(q));
  out.push_back(Tensor::from_f32("prt_scale", {2}, scale));
  BTFC_ASSIGN_OR_RETURN(std::vector<Tensor> base, m->gpu_tensors());
  for (Tensor& t : base)
    if (t.name == "cluster_index" || t.name == "weights") out.push_back(std::move(t));
  return out;
}

Result<std::vector<float>> LpcaModel::relight(const EnvironmentSH& env, const Vec3& view_dir) const {
  int w = 0, h = 0;
  return btfc::relight(*this, env, view_dir, w, h);
}

Status LpcaModel::attach_environment(const EnvironmentSH& env) { return btfc::attach_environment(*this, env); }

Status attach_environment(Model& model, const EnvironmentSH& env, const RelightOptions& opt) {
  auto* m = dynamic_cast<LpcaModel*>(&model);
  if (!m) return invalid_argument("attach_environment needs an lpca model, got '" + model.spec() + "'");
  BTFC_ASSIGN_OR_RETURN(std::vector<Tensor> t, prt_tensors(model, env, opt));
  m->set_prt(std::move(t));
  return {};
}

}  // namespace btfc
