// lpyr model: evaluation at continuous level of detail (paper eq. 7), decoding, storage,
// loading with validation, and the section 3.3 GPU maps. Layouts are pinned in lpyr.h.
#include <Imath/half.h>

#include <algorithm>
#include <cmath>

#include "codecs/eval_grouped.h"
#include "codecs/lpyr/lpyr_internal.h"
#include "core/fixed_product.h"
#include "core/quant.h"

namespace btfc::lpyr {

using Eigen::Index;

Eigen::VectorXf phong_mean(const BtfDesc& d, const Phong& p, float chroma[2], int channel) {
  const size_t nl = d.num_lights(), n = d.num_images();
  Eigen::VectorXf m(static_cast<Index>(n));
  for (size_t r = 0; r < n; ++r)
    m(Index(r)) = channel == k_y ? float(phong_eval(p, d.lights.dirs[r % nl], d.views.dirs[r / nl])) : chroma[channel - 1];
  return m;
}

void quantize(Block& b, bool half) {
  b.scale.resize(b.D.cols());
  for (Index c = 0; c < b.D.cols(); ++c) {
    const float mx = b.D.rows() ? b.D.col(c).cwiseAbs().maxCoeff() : 0.0f;
    b.scale(c) = (half && mx > 0 && std::isfinite(mx)) ? mx : 1.0f;
  }
  if (!half) return;
  auto round_half = [](float x) { return float(Imath::half(x)); };
  b.E = b.E.unaryExpr(round_half);
  for (Index c = 0; c < b.D.cols(); ++c) {
    const float s = b.scale(c);
    b.D.col(c) = b.D.col(c).unaryExpr([&](float x) { return round_half(x / s) * s; });
  }
}

namespace {
std::string tname(const char* what, int k, int c) { return std::string(what) + "." + std::to_string(k) + "." + k_channel_names[c]; }
}  // namespace

Status quantize_q(Block& b, int k, int c, double step) {
  const Index C = b.E.cols();
  std::vector<float> es(static_cast<size_t>(C)), ds(static_cast<size_t>(C));
  for (Index j = 0; j < C; ++j) {
    const double sigma = b.D.col(j).cast<double>().norm();
    const double emax = b.E.rows() ? double(b.E.col(j).cwiseAbs().maxCoeff()) : 0.0;
    const double dmax = b.D.rows() ? double(b.D.col(j).cwiseAbs().maxCoeff()) : 0.0;
    es[size_t(j)] = quant::safe_step(sigma > 0 ? std::min(4.0, step / sigma) : 4.0, emax);
    ds[size_t(j)] = quant::safe_step(step, dmax);
  }
  std::vector<float> deq;
  BTFC_ASSIGN_OR_RETURN(Tensor te, quant::encode(tname("E", k, c), {uint64_t(b.E.rows()), uint64_t(C)}, b.E.data(), es, {}, 19, &deq));
  b.E = Eigen::Map<MatrixXfR>(deq.data(), b.E.rows(), C);
  BTFC_ASSIGN_OR_RETURN(Tensor td, quant::encode(tname("D", k, c), {uint64_t(b.D.rows()), uint64_t(C)}, b.D.data(), ds, {}, 19, &deq));
  b.D = Eigen::Map<MatrixXfR>(deq.data(), b.D.rows(), C);
  b.scale = Eigen::VectorXf::Ones(C);
  b.coded.insert(b.coded.begin(), {std::move(te), std::move(td)});
  return {};
}

Status quantize_mean_q(Block& b, int k, int c, double step) {
  const double mx = b.mean.size() ? double(b.mean.cwiseAbs().maxCoeff()) : 0.0;
  std::vector<float> deq;
  BTFC_ASSIGN_OR_RETURN(Tensor t, quant::encode(tname("mean", k, c), {uint64_t(b.mean.size()), 1}, b.mean.data(), {quant::safe_step(step, mx)}, {}, 19, &deq));
  b.mean = Eigen::Map<Eigen::VectorXf>(deq.data(), Index(deq.size()));
  b.coded.push_back(std::move(t));
  return {};
}

LpyrModel::LpyrModel(BtfDesc desc, std::string spec, Config cfg, std::vector<Level> levels, bool phong, Phong ph, float chroma[2])
    : m_desc(std::move(desc)), m_spec(std::move(spec)), m_cfg(cfg), m_levels(std::move(levels)), m_phong(phong), m_ph(ph),
      m_light_interp(m_desc.lights), m_view_interp(m_desc.views) {
  m_chroma[0] = chroma[0], m_chroma[1] = chroma[1];
  if (m_phong)
    for (int c = 0; c < 3; ++c) m_levels.back().ch[c].mean = phong_mean(m_desc, m_ph, m_chroma, c);
}

Status LpyrModel::check_lod(double lod) const {
  if (!(lod >= 0 && lod <= double(lmax())))
    return invalid_argument("lod " + std::to_string(lod) + " outside [0, " + std::to_string(lmax()) + "] (lpyr levels of this model)");
  return {};
}

void LpyrModel::eval_ycc(int x, int y, size_t row, double lod, float* ycc) const {
  const Index r = Index(row);
  for (int c = 0; c < 3; ++c) {
    float acc = 0;
    for (int k = int(std::floor(lod)); k <= lmax(); ++k) {
      const float w = float(level_weight(lod, k));
      if (w == 0) continue;
      const Level& lv = m_levels[size_t(k)];
      const Block& b = lv.ch[c];
      const Index t = Index(x >> k) + Index(lv.size.w) * Index(y >> k);
      float v = b.D.row(t).dot(b.E.row(r));
      if (b.mean.size()) v += b.mean(r);
      acc += w * v;
    }
    ycc[c] = acc;
  }
}

void LpyrModel::eval(int x, int y, int light, int view, float* out) const {
  float ycc[3];
  eval_ycc(x, y, size_t(light) + m_desc.num_lights() * size_t(view), 0.0, ycc);
  ycbcr_to_rgb(ycc, out);
}

Status LpyrModel::eval_lod(int x, int y, int light, int view, double lod, float* out) const {
  BTFC_RETURN_IF_ERROR(check_lod(lod));
  if (x < 0 || y < 0 || x >= m_desc.width || y >= m_desc.height || light < 0 || view < 0 ||
      size_t(light) >= m_desc.num_lights() || size_t(view) >= m_desc.num_views())
    return invalid_argument("lpyr eval: texel or direction index out of range");
  float ycc[3];
  eval_ycc(x, y, size_t(light) + m_desc.num_lights() * size_t(view), lod, ycc);
  ycbcr_to_rgb(ycc, out);
  return {};
}

Status LpyrModel::eval_dir(int x, int y, const Vec3& wl, const Vec3& wv, float* out) const {
  if (x < 0 || y < 0 || x >= m_desc.width || y >= m_desc.height)
    return invalid_argument("texel (" + std::to_string(x) + ", " + std::to_string(y) + ") outside the BTF");
  const DirWeights a = m_light_interp.weights(wl), b = m_view_interp.weights(wv);
  float acc[3] = {0, 0, 0}, tmp[3];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      const float w = a.weight[size_t(i)] * b.weight[size_t(j)];
      if (w == 0) continue;
      eval(x, y, a.index[size_t(i)], b.index[size_t(j)], tmp);
      for (int c = 0; c < 3; ++c) acc[c] += w * tmp[c];
    }
  std::copy(acc, acc + 3, out);
  return {};
}

namespace {

// sum_p w[p] (d . E.row(row[p]) + mean[row[p]]) over a level's c components (mean may be null);
// C is c as a constant for the small counts lpyr's levels have (with a run-time count GCC's loop
// of 2-8 values was most of a query, perf), 0 for any other count.
template <int C>
float blend_fixed(const float* d, const float* E, size_t c, const float* mean, const size_t* row, const float* w, int np) {
  const size_t n = C > 0 ? size_t(C) : c;
  float acc = 0;
  for (int p = 0; p < np; ++p) {
    const float* er = E + row[p] * n;
    float v = 0;
    for (size_t i = 0; i < n; ++i) v += d[i] * er[i];
    if (mean) v += mean[row[p]];
    acc += w[p] * v;
  }
  return acc;
}
float blend_pairs(const float* d, const float* E, size_t C, const float* mean, const size_t* row, const float* w, int np) {
  switch (C) {
    case 1: return blend_fixed<1>(d, E, C, mean, row, w, np);
    case 2: return blend_fixed<2>(d, E, C, mean, row, w, np);
    case 3: return blend_fixed<3>(d, E, C, mean, row, w, np);
    case 4: return blend_fixed<4>(d, E, C, mean, row, w, np);
    case 6: return blend_fixed<6>(d, E, C, mean, row, w, np);
    case 8: return blend_fixed<8>(d, E, C, mean, row, w, np);
    case 12: return blend_fixed<12>(d, E, C, mean, row, w, np);
    case 16: return blend_fixed<16>(d, E, C, mean, row, w, np);
    default: return blend_fixed<0>(d, E, C, mean, row, w, np);
  }
}

}  // namespace

// Random queries (issue 24, `bench_eval`'s every-codec table): the generic loop ran eval_dir per
// query, whose 9 pairs each went through eval() (Eigen dots of 2-16 values, a level weight in
// double and a YCbCr conversion per pair, the directions located one call at a time): 4.3-4.7 M
// evals/s on 2 cores on the textile's model, ~1400 cycles per query for ~320 multiply-adds. Here
// the directions are located in groups (weights_batch: weights()'s bits), and each channel's
// levels blend the pairs in plain loops over their C components, converted to RGB once. The same
// terms as eval_dir (every level at weight 1 at lod 0), summed in another order.
Status LpyrModel::eval_batch(std::span<const EvalQuery> q, float* out) const {
  BTFC_RETURN_IF_ERROR(check_eval_queries(m_desc, q));
  const size_t nl = m_desc.num_lights();
  eval_grouped(*this, m_light_interp, m_view_interp, q, out, [&](const EvalQuery& e, const DirWeights& wa, const DirWeights& wb, float* o) {
    size_t row[9];
    float w[9];
    int np = 0;
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) {
        const float ww = wa.weight[size_t(a)] * wb.weight[size_t(b)];
        if (ww == 0) continue;
        row[np] = size_t(wa.index[size_t(a)]) + nl * size_t(wb.index[size_t(b)]), w[np++] = ww;
      }
    float ycc[3];
    for (int c = 0; c < 3; ++c) {
      float acc = 0;
      for (int lv = 0; lv <= lmax(); ++lv) {
        const Level& l = m_levels[size_t(lv)];
        const Block& b = l.ch[c];
        const size_t C = size_t(b.E.cols());
        const float* d = b.D.data() + (size_t(e.x >> lv) + size_t(l.size.w) * size_t(e.y >> lv)) * C;
        acc += blend_pairs(d, b.E.data(), C, b.mean.size() ? b.mean.data() : nullptr, row, w, np);
      }
      ycc[c] = acc;
    }
    ycbcr_to_rgb(ycc, o);
  });
  return {};
}

// All weighted levels of a channel are one GEMM: [w_k D_k(p >> k)]_k (texels x sum C) times
// [E_k]_k^T (sum C x directions), plus the weighted sum of the means.
Status LpyrModel::decode(const DecodeRequest& req, Btf& out) const {
  BTFC_RETURN_IF_ERROR(check_lod(req.lod));
  BTFC_ASSIGN_OR_RETURN(ResolvedRequest rr, resolve_request(m_desc, req));
  BTFC_RETURN_IF_ERROR(prepare_output(rr.desc, out));
  const Index nl = Index(rr.lights.size()), nv = Index(rr.views.size()), dout = nl * nv;
  const Index w = rr.desc.width, n = Index(rr.desc.num_texels());
  const int k0 = int(std::floor(req.lod));
  std::vector<int> ks;
  for (int k = k0; k <= lmax(); ++k)
    if (level_weight(req.lod, k) > 0) ks.push_back(k);
  MatrixXfR Ecat[3];
  Eigen::VectorXf mean[3];
  std::vector<Index> offset[3];
  for (int c = 0; c < 3; ++c) {
    Index ctot = 0;
    for (int k : ks) offset[c].push_back(ctot), ctot += m_levels[size_t(k)].ch[c].E.cols();
    Ecat[c].resize(dout, ctot);
    mean[c] = Eigen::VectorXf::Zero(dout);
    for (Index v = 0; v < nv; ++v)
      for (Index l = 0; l < nl; ++l) {
        const Index src = rr.lights[size_t(l)] + Index(m_desc.num_lights()) * rr.views[size_t(v)], dst = l + nl * v;
        for (size_t i = 0; i < ks.size(); ++i) {
          const Block& b = m_levels[size_t(ks[i])].ch[c];
          Ecat[c].row(dst).segment(offset[c][i], b.E.cols()) = b.E.row(src);
          if (b.mean.size()) mean[c](dst) += float(level_weight(req.lod, ks[i])) * b.mean(src);
        }
      }
  }
  // Transposed once (components x rows) for fixed_order_product: a texel's values must not
  // depend on the tile it falls in, so that band-wise decodes equal whole decodes bit for bit.
  MatrixXfR EcatT[3];
  for (int c = 0; c < 3; ++c) EcatT[c] = Ecat[c].transpose();
  const Index tb = 1024;
  MatrixXfR Dcat, ch[3];
  for (Index t0 = 0; t0 < n; t0 += tb) {
    const Index nb = std::min(tb, n - t0);
    for (int c = 0; c < 3; ++c) {
      Dcat.resize(nb, Ecat[c].cols());
      for (Index i = 0; i < nb; ++i) {
        const int x = rr.x0 + int((t0 + i) % w), y = rr.y0 + int((t0 + i) / w);
        for (size_t j = 0; j < ks.size(); ++j) {
          const int k = ks[j];
          const Level& lv = m_levels[size_t(k)];
          const Index t = Index(x >> k) + Index(lv.size.w) * Index(y >> k);
          Dcat.row(i).segment(offset[c][j], lv.ch[c].D.cols()) = float(level_weight(req.lod, k)) * lv.ch[c].D.row(t);
        }
      }
      ch[c].resize(nb, dout);
      fixed_order_product(Dcat.data(), size_t(nb), size_t(Dcat.cols()), size_t(Dcat.cols()), EcatT[c].data(), size_t(dout),
                          ch[c].data(), size_t(dout));
      ch[c].rowwise() += mean[c].transpose();
    }
    float* dst = out.data() + size_t(t0) * size_t(3 * dout);
#pragma omp parallel for schedule(static)
    for (Index i = 0; i < nb; ++i)
      for (Index r = 0; r < dout; ++r) {
        const float ycc[3] = {ch[0](i, r), ch[1](i, r), ch[2](i, r)};
        ycbcr_to_rgb(ycc, dst + size_t(i * dout + r) * 3);
      }
  }
  return {};
}

namespace {
void put_matrix(ContainerWriter& w, const std::string& name, const MatrixXfR& m, bool half) {
  const std::vector<uint64_t> shape{uint64_t(m.rows()), uint64_t(m.cols())};
  if (!half) {
    w.add_tensor(Tensor::from_f32(name, shape, m.data()));
    return;
  }
  Tensor t;
  t.name = name;
  t.dtype = DType::f16;
  t.shape = shape;
  t.bytes.resize(size_t(m.size()) * 2);
  for (Index i = 0; i < m.size(); ++i) {
    const uint16_t bits = Imath::half(m.data()[i]).bits();
    t.bytes[size_t(2 * i)] = uint8_t(bits & 0xff);
    t.bytes[size_t(2 * i + 1)] = uint8_t(bits >> 8);
  }
  w.add_tensor(std::move(t));
}
}  // namespace

Status LpyrModel::save(ContainerWriter& w) const {
  std::vector<uint32_t> info;
  for (int k = 0; k <= lmax(); ++k) {
    const Level& lv = m_levels[size_t(k)];
    uint32_t flags = (k == lmax() && m_phong) ? k_flag_phong : 0;
    for (int c = 0; c < 3; ++c) flags |= lv.mean_stored[c] ? (1u << c) : 0u;
    info.insert(info.end(), {uint32_t(lv.size.w), uint32_t(lv.size.h), uint32_t(lv.ch[0].E.cols()), uint32_t(lv.ch[1].E.cols()),
                             uint32_t(lv.ch[2].E.cols()), flags});
  }
  w.add_tensor(Tensor::from_u32("levels", {uint64_t(lmax() + 1), 6}, info.data()));
  for (int k = 0; k <= lmax(); ++k)
    for (int c = 0; c < 3; ++c) {
      const Level& lv = m_levels[size_t(k)];
      const Block& b = lv.ch[c];
      if (m_cfg.bits > 0) {  // precision=q: the zq tensors (E, D, the stored mean)
        if (b.coded.size() != 2u + (lv.mean_stored[c] ? 1u : 0u)) return codec_error("lpyr: precision=q block without its coded tensors");
        for (const Tensor& t : b.coded) w.add_tensor(t);
        continue;
      }
      put_matrix(w, tname("E", k, c), b.E, m_cfg.half);
      put_matrix(w, tname("D", k, c), b.D * b.scale.cwiseInverse().asDiagonal(), m_cfg.half);
      w.add_tensor(Tensor::from_f32(tname("scale", k, c), {uint64_t(b.scale.size())}, b.scale.data()));
      if (lv.mean_stored[c]) w.add_tensor(Tensor::from_f32(tname("mean", k, c), {uint64_t(b.mean.size())}, b.mean.data()));
    }
  if (m_phong) {
    const float ph[6] = {m_ph.ka, m_ph.kd, m_ph.ks, m_ph.alpha, m_chroma[0], m_chroma[1]};
    w.add_tensor(Tensor::from_f32("phong", {6}, ph));
  }
  return {};
}

uint64_t LpyrModel::payload_bytes() const {
  const uint64_t scalar = m_cfg.half ? 2 : 4;
  uint64_t bytes = uint64_t(lmax() + 1) * 6 * 4 + (m_phong ? 24 : 0);
  for (const Level& lv : m_levels)
    for (int c = 0; c < 3; ++c) {
      const Block& b = lv.ch[c];
      if (m_cfg.bits > 0) {
        for (const Tensor& t : b.coded) bytes += t.bytes.size();
        continue;
      }
      bytes += scalar * uint64_t(b.E.size() + b.D.size()) + 4 * uint64_t(b.scale.size());
      if (lv.mean_stored[c]) bytes += 4 * uint64_t(b.mean.size());
    }
  return bytes;
}

Result<std::unique_ptr<Model>> LpyrModel::load(const ContainerReader& rd, Params p) {
  const BtfDesc& d = rd.desc();
  auto bad = [&](const std::string& what) { return corrupt_data(rd.path() + ": lpyr " + what); };
  if (d.channels != 3) return bad("model with " + std::to_string(d.channels) + " channels (needs 3)");
  const TensorInfo* ti = rd.find("levels");
  if (!ti || ti->shape.size() != 2 || ti->shape[1] != 6 || ti->shape[0] == 0 || ti->shape[0] > 64)
    return bad("tensor 'levels' missing or not [lmax+1, 6]");
  BTFC_ASSIGN_OR_RETURN(Tensor lt, rd.read_checked("levels", DType::u32, ti->shape));
  const int lmax = int(ti->shape[0]) - 1;
  std::vector<uint32_t> info(size_t(lmax + 1) * 6);
  std::copy(lt.bytes.begin(), lt.bytes.end(), reinterpret_cast<uint8_t*>(info.data()));
  const std::vector<LevelSize> sizes = level_sizes(d.width, d.height, lmax);
  const uint64_t dd = d.num_images();
  const bool half = p.get("precision") == "half";
  const int bits = p.get("precision") == "q" ? int(p.get_int("bits")) : 0;
  const DType dt = bits > 0 ? DType::zq : half ? DType::f16 : DType::f32;
  const std::string at = rd.path() + ": chunk TNSR '";
  std::vector<Level> levels(size_t(lmax) + 1);
  bool phong = false;
  for (int k = 0; k <= lmax; ++k) {
    const uint32_t* row = &info[size_t(k) * 6];
    Level& lv = levels[size_t(k)];
    lv.size = sizes[size_t(k)];
    if (row[0] != uint32_t(lv.size.w) || row[1] != uint32_t(lv.size.h))
      return bad("level " + std::to_string(k) + " is " + std::to_string(row[0]) + "x" + std::to_string(row[1]) + ", expected " +
                 std::to_string(lv.size.w) + "x" + std::to_string(lv.size.h));
    const uint32_t flags = row[5];
    if ((flags & ~0xfu) || ((flags & k_flag_phong) && k != lmax)) return bad("level " + std::to_string(k) + " has invalid flags");
    if (k == lmax) {
      phong = flags & k_flag_phong;
      if (phong == bool(flags & 7)) return bad("top level must have either a Phong mean or stored means");
    }
    for (int c = 0; c < 3; ++c) {
      const uint64_t C = row[2 + c];
      if (C == 0 || C > 4096 || C > dd) return bad("level " + std::to_string(k) + " channel " + k_channel_names[c] + " has " + std::to_string(C) + " components");
      BTFC_ASSIGN_OR_RETURN(Tensor E, rd.read_checked(tname("E", k, c), dt, {dd, C}));
      BTFC_ASSIGN_OR_RETURN(Tensor D, rd.read_checked(tname("D", k, c), dt, {uint64_t(lv.size.texels()), C}));
      std::vector<float> e, dv, s(static_cast<size_t>(C), 1.0f);
      if (bits > 0) {
        BTFC_ASSIGN_OR_RETURN(e, quant::decode(E, at + E.name + "'"));
        BTFC_ASSIGN_OR_RETURN(dv, quant::decode(D, at + D.name + "'"));
      } else {
        BTFC_ASSIGN_OR_RETURN(Tensor S, rd.read_checked(tname("scale", k, c), DType::f32, {C}));
        BTFC_ASSIGN_OR_RETURN(e, E.to_f32());
        BTFC_ASSIGN_OR_RETURN(dv, D.to_f32());
        BTFC_ASSIGN_OR_RETURN(s, S.to_f32());
      }
      Block& b = lv.ch[c];
      b.E = Eigen::Map<MatrixXfR>(e.data(), Index(dd), Index(C));
      b.D = Eigen::Map<MatrixXfR>(dv.data(), Index(lv.size.texels()), Index(C));
      b.scale = Eigen::Map<Eigen::VectorXf>(s.data(), Index(C));
      for (Index i = 0; i < b.scale.size(); ++i)
        if (!std::isfinite(b.scale(i)) || b.scale(i) <= 0) return bad("tensor '" + tname("scale", k, c) + "' holds a non-positive or non-finite scale");
      if (!b.E.allFinite() || !b.D.allFinite()) return bad("level " + std::to_string(k) + " channel " + k_channel_names[c] + " holds non-finite values");
      if (bits == 0) b.D = b.D * b.scale.asDiagonal();
      else b.coded = {std::move(E), std::move(D)};
      lv.mean_stored[c] = flags & (1u << c);
      if (lv.mean_stored[c]) {
        std::vector<float> m;
        if (bits > 0) {
          BTFC_ASSIGN_OR_RETURN(Tensor M, rd.read_checked(tname("mean", k, c), DType::zq, {dd, 1}));
          BTFC_ASSIGN_OR_RETURN(m, quant::decode(M, at + M.name + "'"));
          b.coded.push_back(std::move(M));
        } else {
          BTFC_ASSIGN_OR_RETURN(Tensor M, rd.read_checked(tname("mean", k, c), DType::f32, {dd}));
          BTFC_ASSIGN_OR_RETURN(m, M.to_f32());
        }
        b.mean = Eigen::Map<Eigen::VectorXf>(m.data(), Index(dd));
        if (!b.mean.allFinite()) return bad("tensor '" + tname("mean", k, c) + "' holds non-finite values");
      } else if (rd.find(tname("mean", k, c))) {
        return bad("tensor '" + tname("mean", k, c) + "' present but its flag is not set");
      }
    }
  }
  Phong ph;
  float chroma[2] = {0, 0};
  if (phong) {
    BTFC_ASSIGN_OR_RETURN(Tensor P, rd.read_checked("phong", DType::f32, {6}));
    BTFC_ASSIGN_OR_RETURN(std::vector<float> v, P.to_f32());
    for (float x : v)
      if (!std::isfinite(x)) return bad("tensor 'phong' holds non-finite values");
    if (v[1] < 0 || v[2] < 0 || v[3] < 1 || v[3] > 1000) return bad("tensor 'phong' outside its bounds (kd, ks >= 0, alpha in [1, 1000])");
    ph = {v[0], v[1], v[2], v[3]};
    chroma[0] = v[4], chroma[1] = v[5];
  }
  auto model = std::make_unique<LpyrModel>(d, p.canonical(), Config{half, bits}, std::move(levels), phong, ph, chroma);
  model->mutable_stats().add("lmax", lmax);
  model->mutable_stats().note("mean", phong ? "phong" : "stored");
  return std::unique_ptr<Model>(std::move(model));
}

}  // namespace btfc::lpyr
