// The fmf model, internal to codecs/fmf: colour constants, the factorized blocks, the stored
// configuration and FmfModel. fmf.h is the public contract; the files are
//   fmf.cpp        the codec: parameters, encode (SVD per block, quantisation), load
//   fmf_model.cpp  the model: decode (OpenCL or the fixed-order C++ reference), eval, save
//   fmf_color.cpp  colour: dfmf's log-luminance / chroma transform, Bonn's colour models,
//                  Bonn factorizations as models (make_fmf_model)
#pragma once
#include <Eigen/Core>
#include <cmath>
#include <cstring>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <vector>

#include "codecs/fmf/fmf.h"
#include "codecs/fmf/fmf_cl.h"
#include "codecs/fmf/fmf_eval.h"
#include "codecs/fmf/fmf_quant.h"
#include "core/interp.h"
#include "core/svd.h"

namespace btfc::fmf {

using Eigen::Index;

constexpr uint32_t k_payload_version = 1;
constexpr float k_drr_eps = 1e-5f;  // Bonn's dynamic-range-reduction epsilon (not stored in DFMF files)

// YUV as Bonn's colour models 1/11 (formats.md 2.2): RGB = M YUV with
// M = [1 0 1.13983; 1 -0.39465 -0.5806; 1 2.03211 0] (the inverse is in fmf_color.cpp).
constexpr float k_rgb_from_yuv[3][3] = {{1, 0, 1.13983f}, {1, -0.39465f, -0.5806f}, {1, 2.03211f, 0}};

// color=dfmf's inverse once the exponential is taken: from ex = exp(Y'), U', V' and the offset e,
// Y = ex - e, (U, V) = (U', V') (Y + e), then RGB. FmfModel::undecorrelate (std::exp) and the
// random-query path (fmf_eval_dfmf.cpp, a polynomial exp) share it.
inline void dfmf_rgb(float ex, float u, float v, float e, float* rgb) {
  const float y = ex - e;
  const float yuv[3] = {y, u * (y + e), v * (y + e)};
  for (int c = 0; c < 3; ++c) rgb[c] = k_rgb_from_yuv[c][0] * yuv[0] + k_rgb_from_yuv[c][1] * yuv[1] + k_rgb_from_yuv[c][2] * yuv[2];
}

// The parameter table (fmf.cpp).
std::span<const ParamSpec> params_table();

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
Config config_from(const Params& p);

class FmfModel final : public Model {
 public:
  FmfModel(BtfDesc desc, std::string spec, Config cfg, std::vector<Block> blocks)
      : m_desc(std::move(desc)), m_spec(std::move(spec)), m_cfg(cfg), m_blocks(std::move(blocks)),
        m_light_interp(m_desc.lights), m_view_interp(m_desc.views) {
    if (m_cfg.quant.bits > 0) quantize_blocks();
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

  // The rgb factors as the CPU throughput path reads them (fmf_eval.h): a copy of U and SxV on
  // transparent huge pages, made on the first call (thread-safe) and kept. Random queries touch
  // 27 rows of U and one of SxV each, scattered over megabytes: on 4 KiB pages nearly every row is
  // a TLB miss, and a miss on a VM walks two page tables (1.5x the blend rate on huge pages,
  // docs/benchmarks.md). The copy costs the factors' size once more, and only when eval_batch
  // runs on the CPU.
  EvalFactors eval_factors() const;

 private:
  void undecorrelate(const float* ylog_u_v, float* rgb) const {
    if (m_cfg.color_model >= 0) return bonn_undecorrelate(m_cfg, ylog_u_v, rgb);
    dfmf_rgb(std::exp(ylog_u_v[0]), ylog_u_v[1], ylog_u_v[2], m_cfg.offset, rgb);
  }

  // precision=q: U and SxV become their zq tensors and the values those decode to
  // (codecs/fmf/fmf_quant.h); the eigen-textures are width x height images for textures=dct.
  // Blocks not yet coded (a loaded model's are) are quantized on two threads (fmf_model.cpp).
  void quantize_blocks();
  Status quantize_block(Block& b) const;
  Status m_quant_status;  // a failed quantize_block: save() reports it

  // The C++ throughput path of eval_batch (rgb mode, validated queries; fmf_eval.cpp), and the
  // conversion of queries to 3 + 3 (index, weight) pairs it shares with the OpenCL path: a query
  // with the same directions as its predecessor reuses its weights (a frame's texels under one
  // light and view), since the two Delaunay lookups cost more than the evaluation.
  Status eval_batch_cpu(std::span<const EvalQuery> q, float* out) const;
  // color=dfmf (own colour model, 3 channels, validated queries): 9 pairs per query evaluated
  // and blended in vector loops (fmf_eval_dfmf.cpp).
  Status eval_batch_dfmf_cpu(std::span<const EvalQuery> q, float* out) const;
  void to_weighted(const EvalQuery* q, size_t n, btfc_fmf_query* out) const;

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
  mutable std::once_flag m_eval_once;
  mutable std::shared_ptr<float> m_eval_copy;
  mutable const uint16_t* m_eval_half = nullptr;  // in m_eval_copy: U as halves, when exact
  // color=dfmf's copy for eval_batch_dfmf_cpu: the three blocks interleaved, on huge pages.
  mutable std::once_flag m_dfmf_once;
  mutable std::shared_ptr<float> m_dfmf_copy;
};

}  // namespace btfc::fmf
