// fmf codec and model; see fmf.h for the paper, the colour modes and the stored tensors.
#include "codecs/fmf/fmf.h"

#include <Eigen/Core>
#include <Imath/half.h>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>

#include <mutex>

#include "codecs/fmf/fmf_cl.h"
#include "codecs/fmf/fmf_quant.h"
#include "codecs/fmf/ooc_fmf.h"
#include "core/svd.h"
#include "core/fixed_product.h"
#include "core/cl_runtime.h"
#include "core/interp.h"
#include "core/quant.h"

namespace btfc {
namespace {

using Eigen::Index;

constexpr uint32_t k_payload_version = 1;
constexpr float k_drr_eps = 1e-5f;  // Bonn's dynamic-range-reduction epsilon (not stored in DFMF files)

// YUV as Bonn's colour models 1/11 (formats.md 2.2): RGB = M YUV with
// M = [1 0 1.13983; 1 -0.39465 -0.5806; 1 2.03211 0]. The forward matrix is M's exact inverse
// (computed, not the rounded textbook YUV coefficients, which would cost 1e-5 relative error).
constexpr float k_rgb_from_yuv[3][3] = {{1, 0, 1.13983f}, {1, -0.39465f, -0.5806f}, {1, 2.03211f, 0}};

struct YuvFromRgb {
  float m[3][3];
  YuvFromRgb() {
    double a[3][3];
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) a[i][j] = k_rgb_from_yuv[i][j];
    const double det = a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1]) - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0]) +
                       a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]);
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) {  // adjugate / det
        const int r0 = (j + 1) % 3, r1 = (j + 2) % 3, c0 = (i + 1) % 3, c1 = (i + 2) % 3;
        m[i][j] = float((a[r0][c0] * a[r1][c1] - a[r0][c1] * a[r1][c0]) / det);
      }
  }
};
const YuvFromRgb k_yuv;

const ParamSpec k_params[] = {
    {"rank", ParamSpec::Type::integer, "32", 1, 4096, {}, "components C kept (upper bound when target_error is set)", true},
    {"chroma_rank", ParamSpec::Type::integer, "0", 0, 4096, {}, "color=dfmf: components of the U and V channels (0 = rank)"},
    {"target_error", ParamSpec::Type::real, "0", 0, 1, {}, "if > 0: smallest rank whose relative L2 error of the data (decoded vs input) is <= this"},
    {"color", ParamSpec::Type::choice, "rgb", 0, 0, {"rgb", "dfmf"}, "rgb: colour in the matrix rows (paper); dfmf: per-channel log-luminance/chroma (Bonn DFMF model 11)"},
    {"svd", ParamSpec::Type::choice, "auto", 0, 0, {"auto", "exact", "randomized"}, "auto: exact when the small side of the matrix is <= 1024, else randomized"},
    {"oversample", ParamSpec::Type::integer, "16", 0, 1024, {}, "randomized SVD: extra sketch columns"},
    {"power_iters", ParamSpec::Type::integer, "4", 0, 32, {}, "randomized SVD: power iterations"},
    {"precision", ParamSpec::Type::choice, "half", 0, 0, {"half", "float", "q"},
     "storage of U and SxV: half / float, or q = per-component quantized integers, zstd-coded (fmf_quant.h)"},
    {"bits", ParamSpec::Type::integer, "8", 2, 20, {}, "precision=q: step = 2^-bits x RMS of the strongest eigen-texture (SxV column), U column k's step / sigma_k (equal error per component)"},
    {"textures", ParamSpec::Type::choice, "plain", 0, 0, {"plain", "dct"}, "precision=q: SxV columns coded as integers (plain) or as 8x8 DCT coefficients of the eigen-texture images (dct)"},
    {"offset", ParamSpec::Type::real, "0", 0, 1e30, {}, "color=dfmf: luminance offset e of Y' = log(Y + e), U' = U / (Y + e); 0 = from the data (sum Y^2 / sum Y); 1e-5 = Bonn's colour model 11 exactly"},
};

struct Block {
  std::string name;
  MatrixXfR U;        // rows x C
  MatrixXfR SxV;      // texels x C, dequantized (scale applied)
  Eigen::VectorXf S;  // C
  Eigen::VectorXf scale;
  std::vector<Tensor> coded;  // precision=q: the zq tensors U.<b>, SxV.<b> as saved (fmf_quant.h)
};

struct Config {
  bool dfmf = false;
  bool half = true;
  fmf::QuantConfig quant;  // precision=q (quant.bits > 0)
  // Bonn colour model of a model made from a Bonn file (make_fmf_model), when it is not the
  // mode's native one (dfmf: 11, rgb: 0); -1 = native. Non-native models decode on the CPU path
  // only and cannot be saved to .btfc.
  int color_model = -1;
  // color=dfmf: the luminance offset e (Y' = log(Y + e), U' = U / (Y + e)); Bonn's model 11 is 1e-5.
  float offset = k_drr_eps;
  float color_mean[3] = {0, 0, 0};
  float color_transform[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
};

// Inverse of Bonn colour models other than 11 (BTFLIB undecorrelate.m, formats.md 2.2).
void bonn_undecorrelate(const Config& cfg, const float* in, float* rgb);

// A spec's offset 0 is "from the data" at encode; a model's spec holds the resolved value, so 0
// there is a file from before the parameter existed: Bonn's 1e-5.
Config config_from(const Params& p) {
  Config c;
  c.dfmf = p.get("color") == "dfmf";
  c.half = p.get("precision") == "half";
  if (p.get("precision") == "q") c.quant.bits = int(p.get_int("bits")), c.quant.dct = p.get("textures") == "dct";
  const double e = p.get_real("offset");
  c.offset = e > 0 ? float(e) : k_drr_eps;
  return c;
}

class FmfModel final : public Model {
 public:
  FmfModel(BtfDesc desc, std::string spec, Config cfg, std::vector<Block> blocks)
      : m_desc(std::move(desc)), m_spec(std::move(spec)), m_cfg(cfg), m_blocks(std::move(blocks)),
        m_light_interp(m_desc.lights), m_view_interp(m_desc.views) {
    if (m_cfg.quant.bits > 0)
      for (Block& b : m_blocks)
        if (b.coded.empty()) quantize_block(b);
  }

  const BtfDesc& desc() const override { return m_desc; }
  const std::string& spec() const override { return m_spec; }
  ModelStats& mutable_stats() { return m_stats; }
  const std::vector<Block>& blocks() const { return m_blocks; }
  const Config& config() const { return m_cfg; }

  void eval(int x, int y, int l, int v, float* out) const override {
    const Index t = Index(x) + Index(m_desc.width) * y;
    if (!m_cfg.dfmf) {
      const Block& b = m_blocks[0];
      for (int c = 0; c < m_desc.channels; ++c)
        out[c] = b.U.row(Index(m_desc.row(l, v, c))).dot(b.SxV.row(t));
      if (m_cfg.color_model == 12)  // Bonn FMF dynamic range reduction
        for (int c = 0; c < m_desc.channels; ++c) out[c] = std::exp(out[c]) - k_drr_eps;
      return;
    }
    const Index r = Index(l) + Index(m_desc.num_lights()) * v;
    float yuv[3];
    for (int k = 0; k < 3; ++k) yuv[k] = m_blocks[k].U.row(r).dot(m_blocks[k].SxV.row(t));
    undecorrelate(yuv, out);
  }

  Status eval_dir(int x, int y, const Vec3& wl, const Vec3& wv, float* out) const override {
    if (x < 0 || y < 0 || x >= m_desc.width || y >= m_desc.height)
      return invalid_argument("texel (" + std::to_string(x) + ", " + std::to_string(y) + ") outside the BTF");
    DirWeights a = m_light_interp.weights(wl), b = m_view_interp.weights(wv);
    float acc[64] = {0}, tmp[64];
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) {
        const float w = a.weight[i] * b.weight[j];
        if (w == 0) continue;
        eval(x, y, a.index[i], b.index[j], tmp);
        for (int c = 0; c < m_desc.channels; ++c) acc[c] += w * tmp[c];
      }
    for (int c = 0; c < m_desc.channels; ++c) out[c] = acc[c];
    return {};
  }

  Status decode(const DecodeRequest& req, Btf& out) const override;
  Status eval_batch(std::span<const EvalQuery> q, float* out) const override;
  Status save(ContainerWriter& w) const override;
  uint64_t payload_bytes() const override {
    uint64_t bytes = 0, scalar = m_cfg.half ? 2 : 4;
    for (const Block& b : m_blocks) {
      if (!b.coded.empty()) {
        for (const Tensor& t : b.coded) bytes += t.bytes.size();
        bytes += 8 * uint64_t(b.S.size());
        continue;
      }
      bytes += scalar * uint64_t(b.U.size() + b.SxV.size()) + 8 * uint64_t(b.S.size());
    }
    return bytes;
  }
  ModelStats stats() const override { return m_stats; }

 private:
  void undecorrelate(const float* ylog_u_v, float* rgb) const {
    if (m_cfg.color_model >= 0) return bonn_undecorrelate(m_cfg, ylog_u_v, rgb);
    const float e = m_cfg.offset, y = std::exp(ylog_u_v[0]) - e;
    const float yuv[3] = {y, ylog_u_v[1] * (y + e), ylog_u_v[2] * (y + e)};
    for (int c = 0; c < 3; ++c)
      rgb[c] = k_rgb_from_yuv[c][0] * yuv[0] + k_rgb_from_yuv[c][1] * yuv[1] + k_rgb_from_yuv[c][2] * yuv[2];
  }

  // The OpenCL kernels (kernels/fmf.cl) hard-code Bonn's offset 1e-5: other dfmf offsets decode
  // on the CPU path.
  bool native_eps() const { return !m_cfg.dfmf || m_cfg.offset == k_drr_eps; }

  // precision=q: U and SxV become their zq tensors and the values those decode to
  // (codecs/fmf/fmf_quant.h); the eigen-textures are width x height images for textures=dct.
  void quantize_block(Block& b) {
    fmf::QuantizedFactors q = fmf::quantize_factors(b.name, b.U, b.SxV, m_cfg.quant, m_desc.width, m_desc.height);
    if (!q.status.ok()) m_quant_status = q.status;
    b.U = std::move(q.U), b.SxV = std::move(q.SxV), b.coded = std::move(q.coded);
    b.scale = Eigen::VectorXf::Ones(b.SxV.cols());
  }
  Status m_quant_status;  // a failed quantize_block: save() reports it

  // The factors in the OpenCL kernels' layout (codecs/fmf/fmf_cl.h), uploaded on first use.
  Result<std::shared_ptr<fmf_cl::DeviceFactors>> device_factors() const;
  fmf_cl::PackedFactors packed() const;
  Status decode_cl(const ResolvedRequest& rr, Btf& out) const;

  BtfDesc m_desc;
  std::string m_spec;
  Config m_cfg;
  std::vector<Block> m_blocks;
  DirectionInterpolator m_light_interp, m_view_interp;
  ModelStats m_stats;
  mutable std::mutex m_cl_mutex;
  mutable std::shared_ptr<fmf_cl::DeviceFactors> m_cl;
};

fmf_cl::PackedFactors FmfModel::packed() const {
  fmf_cl::PackedFactors f;
  f.mode = m_cfg.dfmf ? BTFC_FMF_DFMF : BTFC_FMF_RGB;
  f.blocks = int(m_blocks.size());
  for (const Block& b : m_blocks) f.C = std::max(f.C, int(b.U.cols()));
  f.rows_per_block = int(m_blocks[0].U.rows());
  f.texels = int(m_desc.num_texels());
  f.nL = int(m_desc.num_lights());
  f.nV = int(m_desc.num_views());
  // Blocks with fewer components (dfmf chroma) are zero-padded to the common C.
  f.U.assign(size_t(f.blocks) * f.rows_per_block * f.C, 0.0f);
  f.SxV.assign(size_t(f.blocks) * f.texels * f.C, 0.0f);
  for (int k = 0; k < f.blocks; ++k) {
    const Block& b = m_blocks[size_t(k)];
    for (Index r = 0; r < b.U.rows(); ++r)
      for (Index c = 0; c < b.U.cols(); ++c) f.U[(size_t(k) * f.rows_per_block + size_t(r)) * f.C + size_t(c)] = b.U(r, c);
    for (Index t = 0; t < b.SxV.rows(); ++t)
      for (Index c = 0; c < b.SxV.cols(); ++c) f.SxV[(size_t(k) * f.texels + size_t(t)) * f.C + size_t(c)] = b.SxV(t, c);
  }
  return f;
}

Result<std::shared_ptr<fmf_cl::DeviceFactors>> FmfModel::device_factors() const {
  std::lock_guard<std::mutex> lock(m_cl_mutex);
  if (!m_cl) {
    BTFC_ASSIGN_OR_RETURN(m_cl, fmf_cl::DeviceFactors::upload(packed()));
  }
  return m_cl;
}

Status FmfModel::decode_cl(const ResolvedRequest& rr, Btf& out) const {
  BTFC_ASSIGN_OR_RETURN(auto dev, device_factors());
  std::vector<int> texels(rr.desc.num_texels());
  for (size_t i = 0; i < texels.size(); ++i)
    texels[i] = int((rr.x0 + i % size_t(rr.desc.width)) + size_t(m_desc.width) * (rr.y0 + i / size_t(rr.desc.width)));
  return dev->decode(texels, rr.lights, rr.views, out.data());
}

Status FmfModel::eval_batch(std::span<const EvalQuery> q, float* out) const {
  if (m_desc.channels != 3 || m_cfg.color_model >= 0 || !native_eps() || !ocl::use_opencl()) return Model::eval_batch(q, out);
  // Validate through the reference path's checks, then convert to the kernel's query layout:
  // directions become 3 + 3 (index, weight) pairs (the renderer's index / weight textures).
  std::vector<btfc_fmf_query> kq(q.size());
  for (size_t i = 0; i < q.size(); ++i) {
    const EvalQuery& e = q[i];
    if (e.x < 0 || e.y < 0 || e.x >= m_desc.width || e.y >= m_desc.height || (e.light >= 0) != (e.view >= 0) ||
        (e.light >= 0 && (size_t(e.light) >= m_desc.num_lights() || size_t(e.view) >= m_desc.num_views())))
      return Model::eval_batch(q, out);  // the reference reports the bad query
  }
  // A query with the same directions as its predecessor in its block (a frame's texels under one
  // light and view) reuses its weights: the Delaunay lookups would cost more than the evaluation.
  const size_t qb = 4096;
#pragma omp parallel for schedule(static)
  for (size_t b0 = 0; b0 < q.size(); b0 += qb)
    for (size_t i = b0; i < std::min(q.size(), b0 + qb); ++i) {
      const EvalQuery& e = q[i];
      btfc_fmf_query& k = kq[i];
      if (i > b0 && e.light < 0 && q[i - 1].light < 0 && std::memcmp(&e.wl, &q[i - 1].wl, sizeof(Vec3)) == 0 &&
          std::memcmp(&e.wv, &q[i - 1].wv, sizeof(Vec3)) == 0) {
        k = kq[i - 1];
        k.texel = e.x + m_desc.width * e.y;
        continue;
      }
      k.texel = e.x + m_desc.width * e.y;
      DirWeights a, b;
      if (e.light >= 0) a.index = {e.light, e.light, e.light}, b.index = {e.view, e.view, e.view};
      else a = m_light_interp.weights(e.wl), b = m_view_interp.weights(e.wv);
      for (int j = 0; j < 3; ++j) k.light[j] = a.index[j], k.view[j] = b.index[j], k.wl[j] = a.weight[j], k.wv[j] = b.weight[j];
    }
  // Runs of queries sharing a direction pair go through the blended-rows kernel (fmf_cl.h).
  Status s;
  auto dev = device_factors();
  s = dev.ok() ? dev.value()->eval_batch(kq, out) : dev.status();
  if (s.ok()) return s;
  if (!ocl::fall_back_after(s)) return s;
  return Model::eval_batch(q, out);
}

Status FmfModel::decode(const DecodeRequest& req, Btf& out) const {
  BTFC_ASSIGN_OR_RETURN(ResolvedRequest rr, resolve_request(m_desc, req));
  BTFC_RETURN_IF_ERROR(prepare_output(rr.desc, out));
  if (m_desc.channels == 3 && m_cfg.color_model < 0 && native_eps() && ocl::use_opencl()) {
    Status s = decode_cl(rr, out);
    if (s.ok() || !ocl::fall_back_after(s)) return s;
  }
  // The C++ reference (and the CPU path): per texel block, one Eigen GEMM per factorized block.
  const Index nl = Index(rr.lights.size()), nv = Index(rr.views.size());
  const Index w = rr.desc.width, n = Index(rr.desc.num_texels()), m = Index(rr.desc.abrdf_size());
  const int nc = m_desc.channels;
  // Gather the U rows of the requested directions, in the output's row order.
  const int nblocks = int(m_blocks.size());
  // Stored transposed (components x rows): fixed_order_product's right operand.
  std::vector<MatrixXfR> Usub(nblocks);
  const Index rows_per_block = m_cfg.dfmf ? nl * nv : m;
  for (int k = 0; k < nblocks; ++k) {
    Usub[k].resize(rows_per_block, m_blocks[k].U.cols());
    for (Index v = 0; v < nv; ++v)
      for (Index l = 0; l < nl; ++l) {
        if (m_cfg.dfmf) {
          Usub[k].row(l + nl * v) = m_blocks[k].U.row(rr.lights[l] + Index(m_desc.num_lights()) * rr.views[v]);
        } else {
          for (int c = 0; c < nc; ++c)
            Usub[k].row(c + nc * (l + nl * v)) = m_blocks[k].U.row(Index(m_desc.row(rr.lights[l], rr.views[v], c)));
        }
      }
    Usub[k] = Usub[k].transpose().eval();
  }
  // Texel blocks bound the temporary memory; each block is one GEMM per factorized channel.
  // Texel tiles of at most ~16 M temporary floats per channel (64 MB), and buffers reused across
  // tiles: fresh memory is slow to fault in on the VMs btfc runs on, and a 4096-texel tile of a
  // UBO2014 per-channel model would need 1.1 GB of temporaries.
  const Index tb = std::clamp<Index>((Index(16) << 20) / std::max<Index>(1, rows_per_block), 16, 4096);
  std::vector<MatrixXfR> sx(nblocks);
  MatrixXfR ch[3];
  for (Index t0 = 0; t0 < n; t0 += tb) {
    const Index nb = std::min(tb, n - t0);
    for (int k = 0; k < nblocks; ++k) {
      sx[k].resize(nb, m_blocks[k].SxV.cols());
      for (Index i = 0; i < nb; ++i) {
        const Index t = t0 + i, sx_t = (rr.x0 + t % w) + Index(m_desc.width) * (rr.y0 + t / w);
        sx[k].row(i) = m_blocks[k].SxV.row(sx_t);
      }
    }
    Eigen::Map<MatrixXfR> dst(out.data() + size_t(t0) * size_t(m), nb, m);
    // fixed_order_product, not a GEMM: a texel's values must not depend on the tile it falls
    // in, so that band-wise (streamed) decodes equal whole decodes bit for bit.
    auto product = [&](int k, float* to) {
      fixed_order_product(sx[k].data(), size_t(nb), size_t(sx[k].cols()), size_t(sx[k].cols()), Usub[k].data(),
                          size_t(rows_per_block), to, size_t(rows_per_block));
    };
    if (!m_cfg.dfmf) {
      product(0, dst.data());
      if (m_cfg.color_model == 12) dst = (dst.array().exp() - k_drr_eps).matrix();  // Bonn FMF dynamic range reduction
      continue;
    }
    for (int k = 0; k < 3; ++k) {
      ch[k].resize(nb, rows_per_block);  // no reallocation when the size is unchanged
      product(k, ch[k].data());
    }
#pragma omp parallel for schedule(static)
    for (Index i = 0; i < nb; ++i)
      for (Index r = 0; r < rows_per_block; ++r) {
        const float in[3] = {ch[0](i, r), ch[1](i, r), ch[2](i, r)};
        undecorrelate(in, &dst(i, 3 * r));
      }
  }
  return {};
}

Status FmfModel::save(ContainerWriter& w) const {
  BTFC_RETURN_IF_ERROR(m_quant_status);
  if (m_cfg.color_model >= 0)
    return unsupported("fmf: a model with Bonn colour model " + std::to_string(m_cfg.color_model) +
                       " cannot be saved as .btfc (only 11 = color=dfmf and 0 = color=rgb); decompress and re-compress it instead");
  for (const Block& b : m_blocks) {
    const uint64_t rows = uint64_t(b.U.rows()), cols = uint64_t(b.U.cols()), texels = uint64_t(b.SxV.rows());
    if (!b.coded.empty()) {  // precision=q: the zq tensors made when quantizing
      for (const Tensor& t : b.coded) w.add_tensor(t);
      w.add_tensor(Tensor::from_f32("scale." + b.name, {cols}, b.scale.data()));
      w.add_tensor(Tensor::from_f32("S." + b.name, {cols}, b.S.data()));
      continue;
    }
    MatrixXfR sxv_scaled = b.SxV * b.scale.cwiseInverse().asDiagonal();
    auto put = [&](const std::string& name, const MatrixXfR& M, std::vector<uint64_t> shape) {
      if (!m_cfg.half) {
        w.add_tensor(Tensor::from_f32(name, std::move(shape), M.data()));
        return;
      }
      Tensor t;
      t.name = name;
      t.dtype = DType::f16;
      t.shape = std::move(shape);
      t.bytes.resize(size_t(M.size()) * 2);
      for (Index i = 0; i < M.size(); ++i) {
        uint16_t bits = Imath::half(M.data()[i]).bits();
        t.bytes[2 * i] = uint8_t(bits & 0xff);
        t.bytes[2 * i + 1] = uint8_t(bits >> 8);
      }
      w.add_tensor(std::move(t));
    };
    put("U." + b.name, b.U, {rows, cols});
    put("SxV." + b.name, sxv_scaled, {texels, cols});
    w.add_tensor(Tensor::from_f32("scale." + b.name, {cols}, b.scale.data()));
    w.add_tensor(Tensor::from_f32("S." + b.name, {cols}, b.S.data()));
  }
  return {};
}

// Rounds U and SxV to their storage precision, so the in-memory model is what the file holds.
// (precision=q is float here: FmfModel's constructor quantizes it, knowing the texture size.)
void quantize(Block& b, bool half) {
  b.scale.resize(b.SxV.cols());
  for (Index c = 0; c < b.SxV.cols(); ++c) {
    const float mx = b.SxV.col(c).cwiseAbs().maxCoeff();
    b.scale(c) = (half && mx > 0 && std::isfinite(mx)) ? mx : 1.0f;
  }
  if (!half) return;
  auto round_half = [](float x) { return float(Imath::half(x)); };
  b.U = b.U.unaryExpr(round_half);
  for (Index c = 0; c < b.SxV.cols(); ++c) {
    const float s = b.scale(c);
    b.SxV.col(c) = b.SxV.col(c).unaryExpr([&](float x) { return round_half(x / s) * s; });
  }
}

// A factorized block from an SVD result, quantised; its statistics go to `stats`.
Block block_from_svd(const std::string& name, SvdResult r, bool half, int max_rank, double target, ModelStats& stats) {
  Block b{name, std::move(r.U), std::move(r.SxV), r.S.cast<float>(), {}, {}};
  quantize(b, half);
  const int kept = int(b.U.cols());
  stats.add("rank." + name, kept);
  stats.add("rel_error." + name, r.rel_error_estimate());
  stats.note("svd." + name, r.method);
  if (kept < max_rank && target == 0)
    stats.note("clamped." + name, "rank " + std::to_string(max_rank) + " clamped to " + std::to_string(kept) +
                                      " (the data's numerical rank limit is " + std::to_string(r.data_rank_limit) + ")");
  if (!r.target_reached) stats.note("target." + name, "target_error not reached at the maximum rank " + std::to_string(max_rank));
  return b;
}

class FmfCodec final : public Codec {
 public:
  const char* name() const override { return "fmf"; }
  const char* summary() const override { return "full matrix factorization (truncated SVD), seed 000 section 4"; }
  uint32_t payload_version() const override { return k_payload_version; }
  std::span<const ParamSpec> params() const override { return k_params; }
  // --max-bytes tries half floats and quantized factors at several bit depths (fmf_quant.h),
  // the rank searched for each: at a byte budget the best rank / precision pair depends on how
  // fast the data's singular values decay and how noisy it is.
  std::vector<std::string> budget_variants() const override {
    return {"precision=half", "precision=q:bits=8", "precision=q:bits=6", "precision=q:bits=5", "precision=q:bits=4"};
  }
  long long budget_knob_limit(const BtfDesc& d) const override { return components_backed_by_texels(d); }
  const StreamingEncoder* streaming() const override { return &fmf_streaming(); }

  Result<std::unique_ptr<Model>> encode(const Btf& btf, const Params& p, Context& ctx) const override {
    const BtfDesc& d = btf.desc();
    const Config cfg = config_from(p);
    if (cfg.dfmf && d.channels != 3) return invalid_argument("fmf: color=dfmf needs 3 channels, the BTF has " + std::to_string(d.channels));
    BTFC_RETURN_IF_ERROR(btf.check_finite("fmf input"));
    const auto t0 = std::chrono::steady_clock::now();
    SvdOptions opt;
    opt.target_rel_error = p.get_real("target_error");
    opt.oversample = int(p.get_int("oversample"));
    opt.power_iters = int(p.get_int("power_iters"));
    opt.seed = ctx.seed;
    opt.progress = ctx.progress;
    const std::string m = p.get("svd");
    opt.method = m == "exact" ? SvdMethod::exact : m == "randomized" ? SvdMethod::randomized : SvdMethod::automatic;
    const int rank = int(p.get_int("rank")), chroma = int(p.get_int("chroma_rank"));

    std::vector<Block> blocks;
    ModelStats stats;
    // dfmf with target_error: the target is the data's error, which no channel's SVD knows; the
    // channels are factorized at their maximum ranks and truncated afterwards (dfmf_truncate_to_target).
    const bool dfmf_target = cfg.dfmf && opt.target_rel_error > 0;
    auto factor = [&](const std::string& name, const float* B, size_t rows, int max_rank) -> Status {
      opt.max_rank = max_rank;
      SvdOptions o = opt;
      if (dfmf_target) o.target_rel_error = 0;
      BTFC_ASSIGN_OR_RETURN(SvdResult r, truncated_svd(B, rows, d.num_texels(), o));
      blocks.push_back(block_from_svd(name, std::move(r), cfg.half, max_rank, o.target_rel_error, stats));
      return {};
    };
    Params rp = p;
    if (!cfg.dfmf) {
      // The Btf buffer is B (rows = (view, light, colour), columns = texels), column-major.
      BTFC_RETURN_IF_ERROR(factor("rgb", btf.data(), d.abrdf_size(), rank));
    } else {
      const size_t rows = d.num_images(), n = d.num_texels();
      double e = p.get_real("offset");
      if (e <= 0) {
        double sy = 0, sy2 = 0;
#pragma omp parallel for reduction(+ : sy, sy2) schedule(static)
        for (size_t t = 0; t < n; ++t) dfmf_luminance_moments(btf.abrdf(t), rows, &sy, &sy2);
        e = dfmf_auto_offset(sy, sy2);
      }
      BTFC_ASSIGN_OR_RETURN(rp, dfmf_with_offset(p, e));
      const float offset = config_from(rp).offset;
      stats.add("dfmf_offset", offset);
      // One decorrelated channel matrix at a time keeps peak memory at input + 1/3 input.
      std::vector<float> ch(rows * n);
      size_t clamped = 0;
      for (int k = 0; k < 3; ++k) {
#pragma omp parallel for reduction(+ : clamped) schedule(static)
        for (size_t t = 0; t < n; ++t) {
          const size_t c = dfmf_channel(btf.abrdf(t), rows, k, offset, &ch[t * rows]);
          if (k == 0) clamped += c;  // the same values clamp in every channel: count them once
        }
        static const char* names[3] = {"y", "u", "v"};
        BTFC_RETURN_IF_ERROR(factor(names[k], ch.data(), rows, k == 0 ? rank : (chroma ? chroma : rank)));
      }
      stats.add("negative_luminance_clamped", double(clamped));
    }
    auto model = std::make_unique<FmfModel>(d, rp.canonical(), config_from(rp), std::move(blocks));
    if (dfmf_target) {
      BTFC_ASSIGN_OR_RETURN(model, truncate_to_target(btf, std::move(model), opt.target_rel_error, stats));
    }
    stats.add("encode_seconds", std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    model->mutable_stats() = std::move(stats);
    return std::unique_ptr<Model>(std::move(model));
  }

  // color=dfmf target_error: the smallest luminance rank ry (chroma ranks scaled alike,
  // ceil(ry * chroma / rank)) whose decoded BTF has a relative L2 error <= target against the
  // input, by bisection over ry (the error falls with the rank on the data this was measured on;
  // each probe decodes the whole BTF). The full-rank model when even it misses the target (noted).
  static Result<std::unique_ptr<FmfModel>> truncate_to_target(const Btf& btf, std::unique_ptr<FmfModel> full, double target,
                                                               ModelStats& stats) {
    const std::vector<Block>& fb = full->blocks();
    const int ry_max = int(fb[0].U.cols()), rc_max = int(std::max(fb[1].U.cols(), fb[2].U.cols()));
    double norm2 = 0;
    for (size_t i = 0; i < btf.size(); ++i) norm2 += double(btf.data()[i]) * btf.data()[i];
    auto make = [&](int ry) {
      const int rc = std::max(1, int(std::ceil(double(ry) * rc_max / ry_max)));
      std::vector<Block> bs;
      for (size_t k = 0; k < 3; ++k) {
        const Block& b = fb[k];
        const Index c = std::min<Index>(b.U.cols(), k == 0 ? ry : rc);
        bs.push_back({b.name, b.U.leftCols(c), b.SxV.leftCols(c), b.S.head(c), b.scale.head(c)});
      }
      return std::make_unique<FmfModel>(full->desc(), full->spec(), full->config(), std::move(bs));
    };
    auto error_of = [&](const FmfModel& m) -> Result<double> {
      Btf dec;
      BTFC_RETURN_IF_ERROR(m.decode_all(dec));
      double e2 = 0;
#pragma omp parallel for reduction(+ : e2) schedule(static)
      for (size_t i = 0; i < btf.size(); ++i) {
        const double df = double(dec.data()[i]) - btf.data()[i];
        e2 += df * df;
      }
      return norm2 > 0 ? std::sqrt(e2 / norm2) : std::sqrt(e2);
    };
    BTFC_ASSIGN_OR_RETURN(double err_hi, error_of(*full));
    if (err_hi > target) {
      stats.note("target.data", "target_error " + std::to_string(target) + " not reached: the maximum ranks give " + std::to_string(err_hi));
      stats.add("data_rel_error", err_hi);
      return full;
    }
    int lo = 0, hi = ry_max;  // invariant: hi meets the target, lo does not (0 = none tried)
    double best = err_hi;
    while (hi - lo > 1) {
      const int mid = lo + (hi - lo) / 2;
      BTFC_ASSIGN_OR_RETURN(double e, error_of(*make(mid)));
      if (e <= target) hi = mid, best = e;
      else lo = mid;
    }
    stats.add("data_rel_error", best);
    std::unique_ptr<FmfModel> m = hi == ry_max ? std::move(full) : make(hi);
    for (auto& [k, v] : stats.numbers)  // the ranks the model keeps, in place of the maximum ones
      for (const Block& b : m->blocks())
        if (k == "rank." + b.name) v = double(b.U.cols());
    return m;
  }

  Result<std::unique_ptr<Model>> load(const ContainerReader& rd) const override {
    if (rd.codec().payload_version > k_payload_version)
      return unsupported(rd.path() + ": fmf payload version " + std::to_string(rd.codec().payload_version) +
                         " is newer than this btfc supports (" + std::to_string(k_payload_version) + ")");
    BTFC_ASSIGN_OR_RETURN(auto spec, parse_spec_string(rd.codec().spec));
    BTFC_ASSIGN_OR_RETURN(Params p, bind_params(spec, k_params));
    const Config cfg = config_from(p);
    const BtfDesc& d = rd.desc();
    if (cfg.dfmf && d.channels != 3) return corrupt_data(rd.path() + ": fmf color=dfmf with " + std::to_string(d.channels) + " channels");
    const uint64_t rows = cfg.dfmf ? d.num_images() : d.abrdf_size(), texels = d.num_texels();
    std::vector<Block> blocks;
    const DType dt = cfg.half ? DType::f16 : DType::f32;
    for (const char* name : cfg.dfmf ? std::vector<const char*>{"y", "u", "v"} : std::vector<const char*>{"rgb"}) {
      const std::string b = name;
      const TensorInfo* ti = rd.find("U." + b);
      if (!ti || ti->shape.size() != 2) return corrupt_data(rd.path() + ": fmf tensor 'U." + b + "' missing or not 2-D");
      const uint64_t C = ti->shape[1];
      if (C == 0 || C > 4096) return corrupt_data(rd.path() + ": fmf tensor 'U." + b + "' has " + std::to_string(C) + " components");
      const DType want = cfg.quant.bits > 0 ? DType::zq : dt;
      BTFC_ASSIGN_OR_RETURN(Tensor U, rd.read_checked("U." + b, want, {rows, C}));
      BTFC_ASSIGN_OR_RETURN(Tensor SxV, rd.read_checked("SxV." + b, want, {texels, C}));
      BTFC_ASSIGN_OR_RETURN(Tensor scale, rd.read_checked("scale." + b, DType::f32, {C}));
      BTFC_ASSIGN_OR_RETURN(Tensor S, rd.read_checked("S." + b, DType::f32, {C}));
      const std::string at = rd.path() + ": chunk TNSR '";
      BTFC_ASSIGN_OR_RETURN(std::vector<float> u, want == DType::zq ? quant::decode(U, at + U.name + "'") : U.to_f32());
      BTFC_ASSIGN_OR_RETURN(std::vector<float> sxv, want == DType::zq ? quant::decode(SxV, at + SxV.name + "'") : SxV.to_f32());
      BTFC_ASSIGN_OR_RETURN(std::vector<float> sc, scale.to_f32());
      BTFC_ASSIGN_OR_RETURN(std::vector<float> s, S.to_f32());
      Block blk;
      blk.name = b;
      blk.U = Eigen::Map<MatrixXfR>(u.data(), Index(rows), Index(C));
      blk.SxV = Eigen::Map<MatrixXfR>(sxv.data(), Index(texels), Index(C));
      blk.scale = Eigen::Map<Eigen::VectorXf>(sc.data(), Index(C));
      blk.S = Eigen::Map<Eigen::VectorXf>(s.data(), Index(C));
      for (Index c = 0; c < Index(C); ++c) {
        if (!std::isfinite(blk.scale(c)) || blk.scale(c) <= 0) return corrupt_data(rd.path() + ": fmf tensor 'scale." + b + "' holds a non-positive or non-finite scale");
      }
      if (!blk.U.allFinite() || !blk.SxV.allFinite()) return corrupt_data(rd.path() + ": fmf block '" + b + "' holds non-finite values");
      blk.SxV = blk.SxV * blk.scale.asDiagonal();
      if (want == DType::zq) blk.coded = {std::move(U), std::move(SxV)};
      blocks.push_back(std::move(blk));
    }
    auto model = std::make_unique<FmfModel>(d, p.canonical(), cfg, std::move(blocks));
    for (const Block& b : model->blocks()) model->mutable_stats().add("rank." + b.name, double(b.U.cols()));
    return std::unique_ptr<Model>(std::move(model));
  }
};

}  // namespace

const Codec& fmf_codec() {
  static const FmfCodec codec;
  return codec;
}

}  // namespace btfc

// ---- Bonn DFMF / FMF files as fmf models (fmf.h; formats.md 2.2) ----
namespace btfc {
namespace {

void bonn_undecorrelate(const Config& cfg, const float* in, float* rgb) {
  // YCoCg -> RGB (BTFLIB undecorrelate.m, model 4).
  static constexpr float k_rgb_from_ycocg[3][3] = {{1, 1, -1}, {1, 0, 1}, {1, -1, -1}};
  auto mul = [&](const float (*M)[3], const float* v) {
    for (int c = 0; c < 3; ++c) rgb[c] = M[c][0] * v[0] + M[c][1] * v[1] + M[c][2] * v[2];
  };
  switch (cfg.color_model) {
    case 0:
      for (int c = 0; c < 3; ++c) rgb[c] = in[c];
      return;
    case 1:
      return mul(k_rgb_from_yuv, in);
    case 3:  // PCA: row vector times T, plus the mean
      for (int j = 0; j < 3; ++j)
        rgb[j] = in[0] * cfg.color_transform[0][j] + in[1] * cfg.color_transform[1][j] + in[2] * cfg.color_transform[2][j] +
                 cfg.color_mean[j];
      return;
    case 4:
      return mul(k_rgb_from_ycocg, in);
    case 9: {
      const float yuv[3] = {std::exp(in[0]) - k_drr_eps, in[1], in[2]};
      return mul(k_rgb_from_yuv, yuv);
    }
    case 10: {
      // sign(v) * exp(|v| + log eps); sign(0) = 0 as in MATLAB.
      auto unlog = [](float v) { return v == 0 ? 0.0f : std::copysign(k_drr_eps * std::exp(std::fabs(v)), v); };
      const float yuv[3] = {std::exp(in[0]) - k_drr_eps, unlog(in[1]), unlog(in[2])};
      return mul(k_rgb_from_yuv, yuv);
    }
    case 12:
      for (int c = 0; c < 3; ++c) rgb[c] = std::exp(in[c]) - k_drr_eps;
      return;
    default:  // 11 never reaches here (native); make_fmf_model rejects the rest
      for (int c = 0; c < 3; ++c) rgb[c] = 0;
  }
}

}  // namespace

Result<std::unique_ptr<Model>> make_fmf_model(const BtfDesc& desc, int cm, std::vector<FmfFactors> in,
                                              const float color_mean[3], const float color_transform[3][3], bool half) {
  BTFC_RETURN_IF_ERROR(desc.validate());
  const bool per_channel = in.size() == 3;
  if (in.size() != 1 && !per_channel)
    return invalid_argument("fmf: a Bonn factorization needs 1 (rgb) or 3 (per channel) blocks, got " + std::to_string(in.size()));
  if (per_channel && desc.channels != 3)
    return unsupported("fmf: per-channel (DFMF) factorizations are supported for 3 channels only, this one has " +
                       std::to_string(desc.channels));
  const bool ok_model = per_channel ? (cm == 0 || cm == 1 || cm == 3 || cm == 4 || (cm >= 9 && cm <= 12)) : (cm == 0 || cm == 12);
  if (!ok_model)
    return unsupported("fmf: Bonn colour model " + std::to_string(cm) +
                       (cm == 2 ? " (Lab)" : cm == 5 || cm == 6 ? " (spectral)" : "") + " is not supported" +
                       (per_channel ? "" : " for an FMF (one rgb block)"));
  Config cfg;
  cfg.dfmf = per_channel;
  cfg.half = half;
  cfg.color_model = (per_channel && cm == 11) || (!per_channel && cm == 0) ? -1 : cm;
  for (int i = 0; i < 3; ++i) {
    cfg.color_mean[i] = color_mean ? color_mean[i] : 0.0f;
    for (int j = 0; j < 3; ++j) cfg.color_transform[i][j] = color_transform ? color_transform[i][j] : float(i == j);
  }
  const size_t rows = per_channel ? desc.num_images() : desc.abrdf_size(), texels = desc.num_texels();
  std::vector<Block> blocks;
  for (FmfFactors& f : in) {
    const std::string what = "fmf: block '" + f.name + "'";
    if (f.C < 1 || f.C > 4096) return unsupported(what + " has " + std::to_string(f.C) + " components (1..4096 supported)");
    const size_t C = size_t(f.C);
    if (f.U.size() != rows * C || f.SxV.size() != texels * C || f.S.size() != C)
      return invalid_argument(what + ": U, SxV or S size disagrees with " + std::to_string(rows) + " rows, " +
                              std::to_string(texels) + " texels, " + std::to_string(C) + " components");
    Block b;
    b.name = f.name;
    b.U = Eigen::Map<const MatrixXfR>(f.U.data(), Index(rows), Index(C));
    std::vector<float>().swap(f.U);  // release as we go: peak memory = model + one block
    b.SxV = Eigen::Map<const MatrixXfR>(f.SxV.data(), Index(texels), Index(C));
    std::vector<float>().swap(f.SxV);
    b.S = Eigen::Map<const Eigen::VectorXf>(f.S.data(), Index(C));
    // The factors are stored exactly (no per-component scale): a half Bonn file saves to a
    // half .btfc without a second rounding.
    b.scale = Eigen::VectorXf::Ones(Index(C));
    if (!b.U.allFinite() || !b.SxV.allFinite()) return corrupt_data(what + " holds non-finite values");
    blocks.push_back(std::move(b));
  }
  std::string text = per_channel ? "rank=" + std::to_string(blocks[0].U.cols()) + ":chroma_rank=" +
                                       std::to_string(std::max(blocks[1].U.cols(), blocks[2].U.cols())) + ":color=dfmf:offset=" +
                                       std::to_string(k_drr_eps)  // the file's luminance offset (colour model 11's), not "automatic"
                                 : "rank=" + std::to_string(blocks[0].U.cols()) + ":color=rgb";
  text += half ? ":precision=half" : ":precision=float";
  BTFC_ASSIGN_OR_RETURN(auto spec, parse_spec_string("fmf:" + text));
  BTFC_ASSIGN_OR_RETURN(Params p, bind_params(spec, k_params));
  auto model = std::make_unique<FmfModel>(desc, p.canonical(), cfg, std::move(blocks));
  for (const Block& b : model->blocks()) model->mutable_stats().add("rank." + b.name, double(b.U.cols()));
  model->mutable_stats().add("bonn_color_model", cm);
  return std::unique_ptr<Model>(std::move(model));
}

size_t dfmf_channel(const float* abrdf, size_t rows, int k, float offset, float* out) {
  size_t clamped = 0;
  for (size_t r = 0; r < rows; ++r) {
    const float* rgb = abrdf + 3 * r;
    float y = k_yuv.m[0][0] * rgb[0] + k_yuv.m[0][1] * rgb[1] + k_yuv.m[0][2] * rgb[2];
    if (y < 0) y = 0, ++clamped;
    if (k > 0) out[r] = (k_yuv.m[k][0] * rgb[0] + k_yuv.m[k][1] * rgb[1] + k_yuv.m[k][2] * rgb[2]) / (y + offset);
    else out[r] = std::log(y + offset);
  }
  return clamped;
}

void dfmf_luminance_moments(const float* abrdf, size_t rows, double* sum_y, double* sum_y2) {
  double s = 0, s2 = 0;
  for (size_t r = 0; r < rows; ++r) {
    const float* rgb = abrdf + 3 * r;
    const double y = std::max(0.0f, k_yuv.m[0][0] * rgb[0] + k_yuv.m[0][1] * rgb[1] + k_yuv.m[0][2] * rgb[2]);
    s += y, s2 += y * y;
  }
  *sum_y += s, *sum_y2 += s2;
}

double dfmf_auto_offset(double sum_y, double sum_y2) {
  const double e = sum_y > 0 ? sum_y2 / sum_y : 0;
  return std::isfinite(e) && e > k_drr_eps ? e : k_drr_eps;
}

Result<Params> dfmf_with_offset(const Params& p, double offset) {
  BTFC_ASSIGN_OR_RETURN(SpecString spec, parse_spec_string(p.canonical()));
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.9g", offset);
  bool placed = false;
  for (auto& [k, v] : spec.values)
    if (k == "offset") v = buf, placed = true;
  if (!placed) spec.values.emplace_back("offset", buf);
  std::string text = spec.codec;
  for (const auto& [k, v] : spec.values) text += ":" + k + "=" + v;
  BTFC_ASSIGN_OR_RETURN(SpecString again, parse_spec_string(text));
  return bind_params(again, k_params);
}

namespace {

// The model of finished factorizations, one per block of the spec's colour mode, as encode()
// makes it (quantisation, per-block rank / error statistics).
Result<std::unique_ptr<Model>> model_from_svds(const BtfDesc& desc, const Params& p, std::vector<SvdResult> rs, ModelStats stats) {
  const Config cfg = config_from(p);
  const size_t rows = cfg.dfmf ? desc.num_images() : desc.abrdf_size();
  if (rs.size() != (cfg.dfmf ? 3u : 1u)) return invalid_argument("fmf: " + std::to_string(rs.size()) + " factorizations for " + p.canonical());
  if (cfg.dfmf && desc.channels != 3) return invalid_argument("fmf: color=dfmf needs 3 channels, the BTF has " + std::to_string(desc.channels));
  const int rank = int(p.get_int("rank")), chroma = int(p.get_int("chroma_rank"));
  static const char* names[3] = {"y", "u", "v"};
  std::vector<Block> blocks;
  for (size_t k = 0; k < rs.size(); ++k) {
    SvdResult& r = rs[k];
    if (size_t(r.U.rows()) != rows || size_t(r.SxV.rows()) != desc.num_texels() || r.U.cols() != r.SxV.cols())
      return invalid_argument("fmf: factor shapes disagree with the BTF (" + desc.summary() + ")");
    const int max_rank = k == 0 ? rank : (chroma ? chroma : rank);
    blocks.push_back(block_from_svd(cfg.dfmf ? names[k] : "rgb", std::move(r), cfg.half, max_rank, p.get_real("target_error"), stats));
  }
  auto model = std::make_unique<FmfModel>(desc, p.canonical(), cfg, std::move(blocks));
  model->mutable_stats() = std::move(stats);
  return std::unique_ptr<Model>(std::move(model));
}

}  // namespace

Result<std::unique_ptr<Model>> make_fmf_model_from_svd(const BtfDesc& desc, const Params& p, SvdResult r, ModelStats stats) {
  if (config_from(p).dfmf) return unsupported("fmf: make_fmf_model_from_svd builds color=rgb models only (color=dfmf: make_dfmf_model_from_svd)");
  std::vector<SvdResult> rs;
  rs.push_back(std::move(r));
  return model_from_svds(desc, p, std::move(rs), std::move(stats));
}

Result<std::unique_ptr<Model>> make_dfmf_model_from_svd(const BtfDesc& desc, const Params& p, SvdResult y, SvdResult u,
                                                        SvdResult v, ModelStats stats) {
  if (!config_from(p).dfmf) return unsupported("fmf: make_dfmf_model_from_svd builds color=dfmf models only");
  std::vector<SvdResult> rs;
  rs.push_back(std::move(y));
  rs.push_back(std::move(u));
  rs.push_back(std::move(v));
  return model_from_svds(desc, p, std::move(rs), std::move(stats));
}

Result<FmfFactorsView> fmf_factors(const Model& model) {
  const auto* m = dynamic_cast<const FmfModel*>(&model);
  if (!m) return invalid_argument(model.spec() + ": not an fmf model");
  const Config& cfg = m->config();
  FmfFactorsView v;
  v.per_channel = cfg.dfmf;
  v.bonn_color_model = cfg.color_model >= 0 ? cfg.color_model : (cfg.dfmf ? 11 : 0);
  v.half = cfg.half;
  v.drr_eps = cfg.dfmf ? cfg.offset : k_drr_eps;
  for (int i = 0; i < 3; ++i) {
    v.color_mean[i] = cfg.color_mean[i];
    for (int j = 0; j < 3; ++j) v.color_transform[i][j] = cfg.color_transform[i][j];
  }
  for (const Block& b : m->blocks())
    v.blocks.push_back({b.name, b.U.data(), b.SxV.data(), b.S.data(), size_t(b.U.rows()), size_t(b.SxV.rows()), int(b.U.cols())});
  return v;
}

}  // namespace btfc
