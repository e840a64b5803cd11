// lpca codec and model; see lpca.h for the paper, the stored tensors and the frames.
#include "codecs/lpca/lpca.h"

#include <Imath/half.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>

#include "codecs/eval_grouped.h"
#include "codecs/lpca/clustering.h"
#include "codecs/lpca/lpca_model.h"
#include "core/sh.h"
#include "core/blas_env.h"
#include "core/quant.h"

namespace btfc {
namespace lpca {

using Eigen::Index;

namespace {

constexpr uint32_t k_payload_version = 1;

const ParamSpec k_params[] = {
    {"clusters", ParamSpec::Type::integer, "0", 0, 4096, {},
     "clusters K of the local PCA (empty ones are dropped); 0 = from the data: texels / (64 (components + 1)), 1..32"},
    {"components", ParamSpec::Type::integer, "8", 1, 256, {}, "eigen-BRDFs c_B per cluster (besides the mean)", true},
    {"iters", ParamSpec::Type::integer, "10", 1, 1000, {}, "maximum {PCA, reassignment} iterations"},
    {"precision", ParamSpec::Type::choice, "half", 0, 0, {"half", "float", "q"},
     "storage of the eigen-BRDF table and the weights: half / float, or q = per-component quantized integers, zstd-coded (lpca.h)"},
    {"bits", ParamSpec::Type::integer, "8", 2, 20, {},
     "precision=q: weight step = 2^-bits x RMS of the texels' ABRDF norms; eigen-BRDF (cluster k, component i) step / sigma_ki, mean step / sqrt(members) (equal error per value)"},
    {"sh_order", ParamSpec::Type::integer, "5", 1, sh::k_max_order, {}, "spherical-harmonic order n (n^2 coefficients) for relighting / PRT"},
};

// clusters=0: as many clusters as the data pays for. A cluster's mean and c eigen-BRDFs are
// estimated from its member texels, and stored at one ABRDF each: asking for at least
// 64 (c + 1) texels per cluster keeps every basis vector backed by 64 texels (a PCA fitted from
// fewer members fits their noise), and the bases at most 1/64 of the data's values, so they can
// never dominate the payload (at 48 x 48 texels and the paper's 32 x 8 the bases were 95 % of the
// bytes, 16:1). At 256 x 256 texels and c = 8 this gives the paper's 32 clusters.
int clusters_for(size_t texels, int components) {
  const size_t k = texels / (size_t(64) * size_t(components + 1));
  return int(std::clamp<size_t>(k, 1, 32));
}

Config config_from(const Params& p) {
  Config c{int(p.get_int("components")), p.get("precision") == "half", 0, int(p.get_int("sh_order"))};
  if (p.get("precision") == "q") c.bits = int(p.get_int("bits"));
  return c;
}

// Per-column maximum |value| of a row-major [rows, cols] array.
std::vector<double> column_max(const float* v, size_t rows, size_t cols) {
  std::vector<double> mx(cols, 0.0);
  for (size_t r = 0; r < rows; ++r)
    for (size_t k = 0; k < cols; ++k) mx[k] = std::max(mx[k], double(std::fabs(v[r * cols + k])));
  return mx;
}

// Cluster indices as a zq tensor [H, W, 1] of step 1 (exact integers; zstd codes them at about
// their entropy instead of 16 bits).
Result<Tensor> coded_clusters(const BtfDesc& d, const std::vector<uint32_t>& cl) {
  std::vector<float> v(cl.begin(), cl.end());
  return quant::encode("cluster", {uint64_t(d.height), uint64_t(d.width), 1}, v.data(), {1.0f}, {});
}

float round_half(float x) { return float(Imath::half(x)); }

Tensor make_tensor(const std::string& name, DType dt, std::vector<uint64_t> shape, const float* data, size_t n) {
  if (dt == DType::f32) return Tensor::from_f32(name, std::move(shape), data);
  Tensor t;
  t.name = name;
  t.dtype = DType::f16;
  t.shape = std::move(shape);
  t.bytes.resize(n * 2);
  for (size_t i = 0; i < n; ++i) {
    const uint16_t bits = Imath::half(data[i]).bits();
    t.bytes[2 * i] = uint8_t(bits & 0xff);
    t.bytes[2 * i + 1] = uint8_t(bits >> 8);
  }
  return t;
}

Tensor cluster_tensor(const std::string& name, const BtfDesc& d, const std::vector<uint32_t>& cl) {
  Tensor t;
  t.name = name;
  t.dtype = DType::u16;
  t.shape = {uint64_t(d.height), uint64_t(d.width)};
  t.bytes.resize(cl.size() * 2);
  for (size_t i = 0; i < cl.size(); ++i) t.bytes[2 * i] = uint8_t(cl[i] & 0xff), t.bytes[2 * i + 1] = uint8_t(cl[i] >> 8);
  return t;
}

}  // namespace

LpcaModel::LpcaModel(BtfDesc desc, std::string spec, Config cfg, std::vector<uint32_t> cluster_of, MatrixXfR table,
                     MatrixXfR weights, std::vector<float> mean_scale, std::vector<float> weight_scale)
    : m_desc(std::move(desc)), m_spec(std::move(spec)), m_cfg(cfg), m_cluster_of(std::move(cluster_of)), m_table(std::move(table)),
      m_weights(std::move(weights)), m_mean_scale(std::move(mean_scale)), m_weight_scale(std::move(weight_scale)),
      m_light_interp(m_desc.lights), m_view_interp(m_desc.views) {
  m_clusters = int(m_table.rows() / (m_cfg.components + 1));
  m_light_w = sh::hemisphere_cell_weights(m_desc.lights);
  // SH of every table row per (view, channel): one small GEMM (n^2 x lights) x (lights x channels).
  const int n2 = sh::num_coeffs(m_cfg.sh_order), nc = m_desc.channels;
  const Index nl = Index(m_desc.num_lights()), nv = Index(m_desc.num_views()), rows = m_table.rows();
  Eigen::MatrixXf Yw(n2, nl);
  std::vector<double> y(static_cast<size_t>(n2));
  for (Index l = 0; l < nl; ++l) {
    const Vec3& d = m_desc.lights.dirs[size_t(l)];
    sh::eval_basis(m_cfg.sh_order, d.x, d.y, d.z, y.data());
    for (int j = 0; j < n2; ++j) Yw(j, l) = float(m_light_w[size_t(l)] * y[size_t(j)]);
  }
  m_eigen_sh.assign(size_t(rows) * size_t(nv) * size_t(nc) * size_t(n2), 0.f);
#pragma omp parallel for schedule(static)
  for (Index r = 0; r < rows * nv; ++r) {
    const Index row = r / nv, v = r % nv;
    Eigen::Map<const MatrixXfR> F(m_table.row(row).data() + v * nl * nc, nl, nc);  // lights x channels
    const Eigen::MatrixXf S = Yw * F;                                            // n2 x channels
    float* dst = m_eigen_sh.data() + size_t(r) * size_t(nc) * size_t(n2);
    for (int c = 0; c < nc; ++c)
      for (int j = 0; j < n2; ++j) dst[size_t(c) * size_t(n2) + size_t(j)] = S(j, c);
  }
}

const float* LpcaModel::eval_table() const {
  std::call_once(m_eval_once, [&] {
    const size_t c1 = size_t(m_cfg.components) + 1, cols = size_t(m_table.cols());
    m_eval_table.resize(size_t(m_table.size()));
#pragma omp parallel for schedule(static)
    for (Index k = 0; k < Index(m_clusters); ++k)
      for (size_t i = 0; i < c1; ++i) {
        const float* src = m_table.row(Index(size_t(k) * c1 + i)).data();
        float* dst = m_eval_table.data() + size_t(k) * cols * c1 + i;
        for (size_t col = 0; col < cols; ++col) dst[col * c1] = src[col];
      }
  });
  return m_eval_table.data();
}

void LpcaModel::eval(int x, int y, int l, int v, float* out) const {
  const size_t t = size_t(x) + size_t(m_desc.width) * size_t(y);
  const int c = m_cfg.components;
  const size_t c1 = size_t(c) + 1;
  // The channels of (l, v) are adjacent columns: one run of channels * (c + 1) floats.
  const float* e = eval_table() + (size_t(m_cluster_of[t]) * size_t(m_table.cols()) + m_desc.row(size_t(l), size_t(v), 0)) * c1;
  const float* w = m_weights.row(Index(t)).data();
  for (int ch = 0; ch < m_desc.channels; ++ch) {
    const float* p = e + size_t(ch) * c1;
    float s = p[0];
    for (int i = 0; i < c; ++i) s += w[i] * p[1 + i];
    out[ch] = s;
  }
}

Status LpcaModel::eval_dir(int x, int y, const Vec3& wl, const Vec3& wv, float* out) const {
  if (x < 0 || y < 0 || x >= m_desc.width || y >= m_desc.height)
    return invalid_argument("texel (" + std::to_string(x) + ", " + std::to_string(y) + ") outside the BTF");
  const DirWeights a = m_light_interp.weights(wl), b = m_view_interp.weights(wv);
  float acc[64] = {0}, tmp[64];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      const float w = a.weight[size_t(i)] * b.weight[size_t(j)];
      if (w == 0) continue;
      eval(x, y, a.index[size_t(i)], b.index[size_t(j)], tmp);
      for (int c = 0; c < m_desc.channels; ++c) acc[c] += w * tmp[c];
    }
  for (int c = 0; c < m_desc.channels; ++c) out[c] = acc[c];
  return {};
}

namespace {

// acc[ch] += wt (p[0] + sum_i w[i] p[1 + i]) for each channel's run p of c + 1 table values; C is
// c as a constant for the common component counts (a run-time count's loop was much of a
// query), 0 for any other count.
template <int C>
void pair_fixed(const float* e, const float* w, int c, int nc, float wt, float* acc) {
  const int n = C > 0 ? C : c;
  for (int ch = 0; ch < nc; ++ch) {
    const float* p = e + size_t(ch) * size_t(n + 1);
    float s = p[0];
    for (int i = 0; i < n; ++i) s += w[i] * p[1 + i];
    acc[ch] += wt * s;
  }
}
void pair_any(const float* e, const float* w, int c, int nc, float wt, float* acc) {
  switch (c) {
    case 1: return pair_fixed<1>(e, w, c, nc, wt, acc);
    case 2: return pair_fixed<2>(e, w, c, nc, wt, acc);
    case 4: return pair_fixed<4>(e, w, c, nc, wt, acc);
    case 6: return pair_fixed<6>(e, w, c, nc, wt, acc);
    case 8: return pair_fixed<8>(e, w, c, nc, wt, acc);
    case 12: return pair_fixed<12>(e, w, c, nc, wt, acc);
    case 16: return pair_fixed<16>(e, w, c, nc, wt, acc);
    default: return pair_fixed<0>(e, w, c, nc, wt, acc);
  }
}

}  // namespace

// Random queries (issue 24, `bench_eval`'s every-codec table): the generic loop ran eval_dir per
// query, which located its two directions one call at a time and summed each pair through eval()
// with a run-time component count. Here the directions are located in groups (weights_batch:
// weights()'s bits) and each pair's channels are summed in a loop of fixed length where the
// component count is a common one. The same terms as eval_dir in the same order.
Status LpcaModel::eval_batch(std::span<const EvalQuery> q, float* out) const {
  BTFC_RETURN_IF_ERROR(check_eval_queries(m_desc, q));
  const int nc = m_desc.channels, c = m_cfg.components;
  if (nc > 64) return Model::eval_batch(q, out);  // eval_dir's own bound
  const size_t c1 = size_t(c) + 1, cols = size_t(m_table.cols());
  const float* table = eval_table();
  eval_grouped(*this, m_light_interp, m_view_interp, q, out, [&](const EvalQuery& e, const DirWeights& wa, const DirWeights& wb, float* o) {
    const size_t t = size_t(e.x) + size_t(m_desc.width) * size_t(e.y);
    const float* base = table + size_t(m_cluster_of[t]) * cols * c1;
    const float* w = m_weights.row(Index(t)).data();
    float acc[64] = {0};
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) {
        const float wt = wa.weight[size_t(a)] * wb.weight[size_t(b)];
        if (wt == 0) continue;
        pair_any(base + m_desc.row(size_t(wa.index[size_t(a)]), size_t(wb.index[size_t(b)]), 0) * c1, w, c, nc, wt, acc);
      }
    std::copy(acc, acc + nc, o);
  });
  return {};
}

Status LpcaModel::decode(const DecodeRequest& req, Btf& out) const {
  BTFC_ASSIGN_OR_RETURN(ResolvedRequest rr, resolve_request(m_desc, req));
  BTFC_RETURN_IF_ERROR(prepare_output(rr.desc, out));
  const int nc = m_desc.channels, c = m_cfg.components;
  const Index nl = Index(rr.lights.size()), nv = Index(rr.views.size()), m = Index(rr.desc.abrdf_size());
  const bool all_rows = m == Index(m_desc.abrdf_size());
  MatrixXfR sub;  // the table's columns in the output's row order
  if (!all_rows) {
    sub.resize(m_table.rows(), m);
    for (Index v = 0; v < nv; ++v)
      for (Index l = 0; l < nl; ++l)
        for (int ch = 0; ch < nc; ++ch)
          sub.col(ch + nc * (l + nl * v)) = m_table.col(Index(m_desc.row(size_t(rr.lights[size_t(l)]), size_t(rr.views[size_t(v)]), size_t(ch))));
  }
  const MatrixXfR& T = all_rows ? m_table : sub;
  const Index w = rr.desc.width, n = Index(rr.desc.num_texels());
#pragma omp parallel for schedule(static)
  for (Index i = 0; i < n; ++i) {
    const Index t = (rr.x0 + i % w) + Index(m_desc.width) * (rr.y0 + i / w);
    const Index r0 = Index(m_cluster_of[size_t(t)]) * (c + 1);
    Eigen::Map<Eigen::RowVectorXf> dst(out.data() + size_t(i) * size_t(m), m);
    dst = T.row(r0);
    for (int k = 0; k < c; ++k) dst += m_weights(t, k) * T.row(r0 + 1 + k);
  }
  return {};
}

Status LpcaModel::save(ContainerWriter& w) const {
  if (m_cfg.bits > 0) {  // precision=q: the zq tensors made at encode (or read at load)
    if (m_coded.size() != 3) return codec_error("lpca: precision=q model without its coded tensors");
    for (const Tensor& t : m_coded) w.add_tensor(t);
    return {};
  }
  const int c = m_cfg.components, K = m_clusters;
  const DType dt = m_cfg.half ? DType::f16 : DType::f32;
  const uint64_t rows = m_desc.abrdf_size();
  MatrixXfR tq = m_table;
  for (int k = 0; k < K; ++k) tq.row(Index(k) * (c + 1)) /= m_mean_scale[size_t(k)];
  MatrixXfR wq = m_weights;
  for (Index t = 0; t < wq.rows(); ++t)
    for (int i = 0; i < c; ++i) wq(t, i) /= m_weight_scale[size_t(m_cluster_of[size_t(t)]) * size_t(c) + size_t(i)];
  w.add_tensor(cluster_tensor("cluster", m_desc, m_cluster_of));
  w.add_tensor(make_tensor("table", dt, {uint64_t(K), uint64_t(c + 1), rows}, tq.data(), size_t(tq.size())));
  w.add_tensor(Tensor::from_f32("mean_scale", {uint64_t(K)}, m_mean_scale.data()));
  w.add_tensor(make_tensor("weights", dt, {uint64_t(m_desc.height), uint64_t(m_desc.width), uint64_t(c)}, wq.data(), size_t(wq.size())));
  w.add_tensor(Tensor::from_f32("weight_scale", {uint64_t(K), uint64_t(c)}, m_weight_scale.data()));
  return {};
}

uint64_t LpcaModel::payload_bytes() const {
  if (m_cfg.bits > 0) {
    uint64_t bytes = 0;
    for (const Tensor& t : m_coded) bytes += t.bytes.size();
    return bytes;
  }
  const uint64_t scalar = m_cfg.half ? 2 : 4;
  return 2 * uint64_t(m_cluster_of.size()) + scalar * uint64_t(m_table.size() + m_weights.size()) +
         4 * uint64_t(m_mean_scale.size() + m_weight_scale.size());
}

Result<std::vector<Tensor>> LpcaModel::gpu_tensors() const {
  std::vector<Tensor> out;
  const int c = m_cfg.components, n2 = sh::num_coeffs(m_cfg.sh_order);
  out.push_back(cluster_tensor("cluster_index", m_desc, m_cluster_of));
  out.push_back(Tensor::from_f32("weights", {uint64_t(m_desc.height), uint64_t(m_desc.width), uint64_t(c)}, m_weights.data()));
  out.push_back(Tensor::from_f32("eigen_brdfs", {uint64_t(m_clusters), uint64_t(c + 1), m_desc.abrdf_size()}, m_table.data()));
  out.push_back(Tensor::from_f32("eigen_sh", {uint64_t(m_clusters), uint64_t(c + 1), m_desc.num_views(), uint64_t(m_desc.channels), uint64_t(n2)},
                                 m_eigen_sh.data()));
  std::vector<float> vd;
  for (const Vec3& d : m_desc.views.dirs) vd.insert(vd.end(), {d.x, d.y, d.z});
  out.push_back(Tensor::from_f32("view_dirs", {m_desc.num_views(), 3}, vd.data()));
  for (const Tensor& t : m_prt)
    if (t.name == "prt" || t.name == "prt_scale") out.push_back(t);
  return out;
}

namespace {

class LpcaCodec final : public Codec {
 public:
  const char* name() const override { return "lpca"; }
  const char* summary() const override { return "local PCA of ABRDFs + SH relighting / PRT, seed 002 sections 3-5"; }
  uint32_t payload_version() const override { return k_payload_version; }
  std::span<const ParamSpec> params() const override { return k_params; }
  // --max-bytes searches the components (and with them the default cluster count) for half
  // floats and for quantized tables / weights at three bit depths (as fmf does).
  std::vector<std::string> budget_variants(const Params&) const override {
    return {"precision=half", "precision=q:bits=8", "precision=q:bits=6", "precision=q:bits=4"};
  }
  long long budget_knob_limit(const BtfDesc& d) const override { return components_backed_by_texels(d); }

  Result<std::unique_ptr<Model>> encode(const Btf& btf, const Params& p, Context& ctx) const override {
    const BtfDesc& d = btf.desc();
    BTFC_RETURN_IF_ERROR(btf.check_finite("lpca input"));
    if (d.channels > 64) return unsupported("lpca: more than 64 channels");
    const auto t0 = std::chrono::steady_clock::now();
    const Config cfg = config_from(p);
    FitOptions fo;
    fo.clusters = int(p.get_int("clusters"));
    if (fo.clusters == 0) fo.clusters = clusters_for(d.num_texels(), cfg.components);
    fo.components = cfg.components;
    fo.iters = int(p.get_int("iters"));
    fo.seed = ctx.seed;
    fo.progress = ctx.progress;
    // The clustering and the cluster PCAs sum squares in float: a BTF whose largest value lies
    // outside [2^-32, 2^32] is fitted as a copy scaled by a power of two (exact; fit_scale_exponent
    // in core/btf.h), then the means and weights are scaled back (exact), so it gets its
    // normal-range twin's model (a synthetic BTF times 1e-30 or 1e24: relative L2 0.42 / 0.62
    // instead of 0.31 without). The eigen-BRDFs are unit vectors: no scale.
    const float peak = max_abs(btf.data(), btf.size());
    const int k_scale = fit_scale_exponent(peak);
    Btf scaled;
    if (k_scale != 0) {
      auto copy = scaled_copy(btf, k_scale);
      if (!copy.ok()) return copy.status().with_context("lpca: the scaled copy of a BTF whose values pass 2^32 or stay below 2^-32");
      scaled = std::move(copy).value();
    }
    BTFC_ASSIGN_OR_RETURN(FitResult fit, fit_local_pca(k_scale != 0 ? scaled : btf, fo));
    if (k_scale != 0) {
      scaled = Btf();
      for (int k = 0; k < fit.clusters; ++k) {  // the mean rows; the eigen-BRDFs stay unit vectors
        auto mean = fit.table.row(Index(k) * (fit.components + 1));
        scale_by_pow2(mean.data(), mean.data(), size_t(mean.size()), -k_scale);
      }
      scale_by_pow2(fit.weights.data(), fit.weights.data(), size_t(fit.weights.size()), -k_scale);
      fit.total_energy = std::ldexp(fit.total_energy, -2 * k_scale);
      for (double& e : fit.sq_error) e = std::ldexp(e, -2 * k_scale);
    }
    const auto t1 = std::chrono::steady_clock::now();
    const int K = fit.clusters, c = cfg.components;
    const Index dim = Index(d.abrdf_size()), N = Index(d.num_texels());

    // Storage rounding of the table, then the weights re-projected onto the rounded table, so the
    // weights compensate the table's rounding.
    std::vector<float> mean_scale(size_t(K), 1.f), weight_scale(size_t(K) * size_t(c), 1.f);
    if (cfg.half) {
      for (int k = 0; k < K; ++k) {
        auto mean = fit.table.row(Index(k) * (c + 1));
        const float mx = mean.cwiseAbs().maxCoeff();
        if (mx > 0 && std::isfinite(mx)) mean_scale[size_t(k)] = mx;
        const float s = mean_scale[size_t(k)];
        mean = mean.unaryExpr([s](float x) { return round_half(x / s) * s; });
        fit.table.middleRows(Index(k) * (c + 1) + 1, c) = fit.table.middleRows(Index(k) * (c + 1) + 1, c).unaryExpr(&round_half);
      }
    }
    // precision=q (lpca.h): the table as a zq tensor [rows, K (c + 1)] (one column per mean /
    // eigen-BRDF, each with its equal-error step), then the weights re-projected onto the
    // dequantized table, as for half.
    ModelStats st;
    std::vector<Tensor> coded;
    double q_step = 0;  // the weight step D
    if (cfg.bits > 0) {
      q_step = std::ldexp(std::sqrt(std::max(0.0, fit.total_energy) / quant::step_texels(double(N), double(dim))), -cfg.bits);
      if (!(q_step > 0) || !std::isfinite(q_step)) q_step = 1;  // all-zero data: any step is exact
      const Index R = Index(K) * (c + 1);
      std::vector<double> members(size_t(K), 0.0), sigma2(size_t(R), 0.0);
      for (Index t = 0; t < N; ++t) {
        const size_t k = fit.cluster_of[size_t(t)];
        members[k] += 1;
        for (int i = 0; i < c; ++i) sigma2[k * size_t(c + 1) + 1 + size_t(i)] += double(fit.weights(t, i)) * fit.weights(t, i);
      }
      for (int k = 0; k < K; ++k) sigma2[size_t(k) * size_t(c + 1)] = members[size_t(k)];  // the mean's weight is 1 per member
      Eigen::MatrixXf Tc = fit.table;  // column-major R x dim = row-major [dim, R]
      const std::vector<double> mx = column_max(Tc.data(), size_t(dim), size_t(R));
      std::vector<float> steps(static_cast<size_t>(R));
      for (Index r = 0; r < R; ++r) {
        const double sg = std::sqrt(sigma2[size_t(r)]);
        // An eigen-BRDF is a unit vector: a step of 4 rounds it all to zero, no coarser step is
        // needed. A mean is in the data's units (past 4 from a BTF scaled by 1e30): uncapped.
        const bool mean_row = r % (c + 1) == 0;
        steps[size_t(r)] = quant::safe_step(sg > 0 ? (mean_row ? q_step / sg : std::min(4.0, q_step / sg)) : 4.0, mx[size_t(r)]);
      }
      std::vector<float> deq;
      BTFC_ASSIGN_OR_RETURN(Tensor tt, quant::encode("table", {uint64_t(dim), uint64_t(R)}, Tc.data(), steps, {}, 19, &deq));
      fit.table = Eigen::Map<Eigen::MatrixXf>(deq.data(), R, dim);
      coded.push_back(std::move(tt));
    }
    const Eigen::Map<const Eigen::MatrixXf> X(btf.data(), dim, N);
    double err = 0;
    {
      // One BLAS thread per OpenMP thread and per-thread vectors: the per-texel GEMVs with
      // OpenBLAS's own threads and a fresh 79 KB vector per texel took 4 s at 256^2 texels.
      SingleThreadedBlas one_blas_thread;
#pragma omp parallel reduction(+ : err)
      {
        Eigen::VectorXf xc(dim), w(c);
#pragma omp for schedule(static)
        for (Index t = 0; t < N; ++t) {
          const Index r0 = Index(fit.cluster_of[size_t(t)]) * (c + 1);
          xc = X.col(t) - fit.table.row(r0).transpose();
          w.noalias() = fit.table.middleRows(r0 + 1, c) * xc;
          fit.weights.row(t) = w.transpose();
          err += std::max(0.0, xc.cast<double>().squaredNorm() - w.cast<double>().squaredNorm());
        }
      }
    }
    // A weight is a texel's coordinate in its cluster's basis, up to the norm of its centred
    // ABRDF: past 3.4e38 for values near the largest float, which no float model holds.
    if (!fit.weights.allFinite() || !std::isfinite(err)) {
      char top[32];
      std::snprintf(top, sizeof top, "%.3g", double(peak));
      return unsupported(std::string("lpca: the texels' weights overflow float (input values up to ") + top +
                         ", near the largest float 3.4e38): scale the BTF down");
    }
    if (cfg.half) {
      for (int k = 0; k < K; ++k)
        for (int i = 0; i < c; ++i) {
          float mx = 0;
          for (Index t = 0; t < N; ++t)
            if (int(fit.cluster_of[size_t(t)]) == k) mx = std::max(mx, std::abs(fit.weights(t, i)));
          if (mx > 0 && std::isfinite(mx)) weight_scale[size_t(k) * size_t(c) + size_t(i)] = mx;
        }
      for (Index t = 0; t < N; ++t)
        for (int i = 0; i < c; ++i) {
          const float s = weight_scale[size_t(fit.cluster_of[size_t(t)]) * size_t(c) + size_t(i)];
          fit.weights(t, i) = round_half(fit.weights(t, i) / s) * s;
        }
    }
    if (cfg.bits > 0) {
      const std::vector<double> mx = column_max(fit.weights.data(), size_t(N), size_t(c));
      std::vector<float> steps(static_cast<size_t>(c));
      for (int i = 0; i < c; ++i) steps[size_t(i)] = quant::safe_step(q_step, mx[size_t(i)]);
      std::vector<float> deq;
      BTFC_ASSIGN_OR_RETURN(Tensor wt, quant::encode("weights", {uint64_t(d.height), uint64_t(d.width), uint64_t(c)}, fit.weights.data(),
                                                     steps, {}, 19, &deq));
      fit.weights = Eigen::Map<MatrixXfR>(deq.data(), N, c);
      BTFC_ASSIGN_OR_RETURN(Tensor ct, coded_clusters(d, fit.cluster_of));
      coded.insert(coded.begin(), std::move(ct));
      coded.push_back(std::move(wt));
      st.add("q.weight_step", q_step);
    }

    st.add("clusters_requested", double(fo.clusters));
    st.add("clusters_used", double(K));
    st.add("components", double(c));
    st.add("iterations", double(fit.sq_error.size()));
    st.add("converged", fit.converged ? 1 : 0);
    st.add("reseeded", double(fit.reseeded));
    const double total = fit.total_energy > 0 ? fit.total_energy : 1;
    for (size_t i = 0; i < fit.sq_error.size(); ++i) st.add("rel_error.iter" + std::to_string(i), std::sqrt(fit.sq_error[i] / total));
    for (size_t i = 0; i < fit.changes.size(); ++i) st.add("changes.iter" + std::to_string(i), double(fit.changes[i]));
    st.add("rel_error_estimate", std::sqrt(err / total));
    st.add("cluster_seconds", std::chrono::duration<double>(t1 - t0).count());
    st.add("assign_seconds", fit.assign_seconds);
    if (fit.assign_exhaustive > 0) st.add("assign_scored_fraction", double(fit.assign_scored) / double(fit.assign_exhaustive));
    if (K < fo.clusters)
      st.note("clamped.clusters", "clusters=" + std::to_string(fo.clusters) + ": " + std::to_string(fo.clusters - K) + " of them stayed empty (fewer distinct texels than clusters); " +
                                      std::to_string(K) + " used");
    // The spec records the clusters used (clusters=0 resolved, empty ones dropped).
    BTFC_ASSIGN_OR_RETURN(Params used, with_value(p, "clusters", std::to_string(K), k_params));
    auto model = std::make_unique<LpcaModel>(d, used.canonical(), cfg, std::move(fit.cluster_of), std::move(fit.table), std::move(fit.weights),
                                             std::move(mean_scale), std::move(weight_scale));
    model->set_coded(std::move(coded));
    st.add("encode_seconds", std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    model->mutable_stats() = std::move(st);
    return std::unique_ptr<Model>(std::move(model));
  }

  Result<std::unique_ptr<Model>> load(const ContainerReader& rd) const override {
    const std::string& path = rd.path();
    if (rd.codec().payload_version > k_payload_version)
      return unsupported(path + ": lpca payload version " + std::to_string(rd.codec().payload_version) + " is newer than this btfc supports (" +
                         std::to_string(k_payload_version) + ")");
    BTFC_ASSIGN_OR_RETURN(auto spec, parse_spec_string(rd.codec().spec));
    BTFC_ASSIGN_OR_RETURN(Params p, bind_params(spec, k_params));
    const Config cfg = config_from(p);
    const BtfDesc& d = rd.desc();
    if (d.channels > 64) return corrupt_data(path + ": lpca with more than 64 channels");
    const int c = cfg.components;
    if (cfg.bits > 0) return load_q(rd, p, cfg);
    const TensorInfo* ti = rd.find("table");
    if (!ti || ti->shape.size() != 3) return corrupt_data(path + ": lpca tensor 'table' missing or not 3-D");
    const uint64_t K = ti->shape[0];
    if (K == 0 || K > uint64_t(p.get_int("clusters") > 0 ? p.get_int("clusters") : 4096))
      return corrupt_data(path + ": lpca tensor 'table' has " + std::to_string(K) + " clusters (spec allows 1.." + std::to_string(p.get_int("clusters")) + ")");
    const DType dt = cfg.half ? DType::f16 : DType::f32;
    const uint64_t rows = d.abrdf_size(), H = uint64_t(d.height), W = uint64_t(d.width);
    BTFC_ASSIGN_OR_RETURN(Tensor table_t, rd.read_checked("table", dt, {K, uint64_t(c + 1), rows}));
    BTFC_ASSIGN_OR_RETURN(Tensor cluster_t, rd.read_checked("cluster", DType::u16, {H, W}));
    BTFC_ASSIGN_OR_RETURN(Tensor ms_t, rd.read_checked("mean_scale", DType::f32, {K}));
    BTFC_ASSIGN_OR_RETURN(Tensor w_t, rd.read_checked("weights", dt, {H, W, uint64_t(c)}));
    BTFC_ASSIGN_OR_RETURN(Tensor ws_t, rd.read_checked("weight_scale", DType::f32, {K, uint64_t(c)}));
    BTFC_ASSIGN_OR_RETURN(std::vector<float> table, table_t.to_f32());
    BTFC_ASSIGN_OR_RETURN(std::vector<float> wv, w_t.to_f32());
    BTFC_ASSIGN_OR_RETURN(std::vector<float> ms, ms_t.to_f32());
    BTFC_ASSIGN_OR_RETURN(std::vector<float> ws, ws_t.to_f32());
    for (float s : ms)
      if (!std::isfinite(s) || s <= 0) return corrupt_data(path + ": lpca tensor 'mean_scale' holds a non-positive or non-finite scale");
    for (float s : ws)
      if (!std::isfinite(s) || s <= 0) return corrupt_data(path + ": lpca tensor 'weight_scale' holds a non-positive or non-finite scale");
    std::vector<uint32_t> cluster_of(size_t(H * W));
    for (size_t i = 0; i < cluster_of.size(); ++i) {
      cluster_of[i] = uint32_t(cluster_t.bytes[2 * i]) | (uint32_t(cluster_t.bytes[2 * i + 1]) << 8);
      if (cluster_of[i] >= K) return corrupt_data(path + ": lpca tensor 'cluster' holds index " + std::to_string(cluster_of[i]) + " >= " + std::to_string(K) + " clusters");
    }
    MatrixXfR T = Eigen::Map<MatrixXfR>(table.data(), Index(K) * (c + 1), Index(rows));
    MatrixXfR Wt = Eigen::Map<MatrixXfR>(wv.data(), Index(H * W), c);
    if (!T.allFinite()) return corrupt_data(path + ": lpca tensor 'table' holds non-finite values");
    if (!Wt.allFinite()) return corrupt_data(path + ": lpca tensor 'weights' holds non-finite values");
    for (uint64_t k = 0; k < K; ++k) T.row(Index(k) * (c + 1)) *= ms[k];
    for (Index t = 0; t < Wt.rows(); ++t)
      for (int i = 0; i < c; ++i) Wt(t, i) *= ws[size_t(cluster_of[size_t(t)]) * size_t(c) + size_t(i)];
    auto model = std::make_unique<LpcaModel>(d, p.canonical(), cfg, std::move(cluster_of), std::move(T), std::move(Wt), std::move(ms), std::move(ws));
    model->mutable_stats().add("clusters_used", double(K));
    model->mutable_stats().add("components", double(c));
    return std::unique_ptr<Model>(std::move(model));
  }

 private:
  // precision=q: cluster zq [H, W, 1], table zq [rows, K (c + 1)], weights zq [H, W, c].
  static Result<std::unique_ptr<Model>> load_q(const ContainerReader& rd, const Params& p, const Config& cfg) {
    const std::string& path = rd.path();
    const BtfDesc& d = rd.desc();
    const int c = cfg.components;
    const uint64_t rows = d.abrdf_size(), H = uint64_t(d.height), W = uint64_t(d.width);
    const TensorInfo* ti = rd.find("table");
    if (!ti || ti->shape.size() != 2 || ti->shape[0] != rows || ti->shape[1] % uint64_t(c + 1) != 0)
      return corrupt_data(path + ": lpca tensor 'table' missing or not [" + std::to_string(rows) + ", K (c + 1)]");
    const uint64_t K = ti->shape[1] / uint64_t(c + 1);
    if (K == 0 || K > uint64_t(p.get_int("clusters") > 0 ? p.get_int("clusters") : 4096))
      return corrupt_data(path + ": lpca tensor 'table' has " + std::to_string(K) + " clusters (spec allows 1.." + std::to_string(p.get_int("clusters")) + ")");
    BTFC_ASSIGN_OR_RETURN(Tensor table_t, rd.read_checked("table", DType::zq, {rows, K * uint64_t(c + 1)}));
    BTFC_ASSIGN_OR_RETURN(Tensor cluster_t, rd.read_checked("cluster", DType::zq, {H, W, 1}));
    BTFC_ASSIGN_OR_RETURN(Tensor w_t, rd.read_checked("weights", DType::zq, {H, W, uint64_t(c)}));
    const std::string at = path + ": chunk TNSR '";
    BTFC_ASSIGN_OR_RETURN(std::vector<float> table, quant::decode(table_t, at + "table'"));
    BTFC_ASSIGN_OR_RETURN(std::vector<float> cl, quant::decode(cluster_t, at + "cluster'"));
    BTFC_ASSIGN_OR_RETURN(std::vector<float> wv, quant::decode(w_t, at + "weights'"));
    std::vector<uint32_t> cluster_of(cl.size());
    for (size_t i = 0; i < cl.size(); ++i) {
      if (!(cl[i] >= 0 && cl[i] < float(K)) || cl[i] != std::floor(cl[i]))
        return corrupt_data(path + ": lpca tensor 'cluster' holds " + std::to_string(cl[i]) + ", not an index below " + std::to_string(K) + " clusters");
      cluster_of[i] = uint32_t(cl[i]);
    }
    MatrixXfR T = Eigen::Map<Eigen::MatrixXf>(table.data(), Index(K) * (c + 1), Index(rows));
    MatrixXfR Wt = Eigen::Map<MatrixXfR>(wv.data(), Index(H * W), c);
    std::vector<float> ms(size_t(K), 1.f), ws(size_t(K) * size_t(c), 1.f);
    auto model = std::make_unique<LpcaModel>(d, p.canonical(), cfg, std::move(cluster_of), std::move(T), std::move(Wt), std::move(ms), std::move(ws));
    model->set_coded({std::move(cluster_t), std::move(table_t), std::move(w_t)});
    model->mutable_stats().add("clusters_used", double(K));
    model->mutable_stats().add("components", double(c));
    return std::unique_ptr<Model>(std::move(model));
  }
};

}  // namespace
}  // namespace lpca

const Codec& lpca_codec() {
  static const lpca::LpcaCodec codec;
  return codec;
}

}  // namespace btfc
