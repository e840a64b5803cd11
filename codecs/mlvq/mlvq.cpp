// mlvq codec: parameters, the scheme choice (`scheme=best`), HDR detection, loading.
// See mlvq.h for the paper and the pipeline.
#include "codecs/mlvq/mlvq.h"

#include <chrono>
#include <cmath>

#include "codecs/mlvq/mlvq_internal.h"
#include "core/cl_runtime.h"

namespace btfc {
namespace mlvq {

namespace {

const ParamSpec k_params[] = {
    {"scheme", ParamSpec::Type::choice, "best", 0, 0, {"best", "1", "2", "3", "4"},
     "level at which luminance and chromaticity split (paper Fig. 2); best = encode with all four, keep the smallest"},
    {"ssim4", ParamSpec::Type::real, "0.9", 0, 1, {}, "SSIM threshold for reusing a 4D codebook entry (per texel)"},
    {"ssim3", ParamSpec::Type::real, "0.9", 0, 1, {}, "SSIM threshold for 3D entries (per view azimuth)"},
    {"ssim2", ParamSpec::Type::real, "0.95", 0, 1, {}, "SSIM threshold for 2D entries (per view elevation)"},
    {"ssim1", ParamSpec::Type::real, "0.98", 0, 1, {}, "SSIM threshold for 1D entries (per light alpha)", true},
    {"phi", ParamSpec::Type::integer, "16", 1, 64, {}, "view azimuth nodes (level 4)"},
    {"theta", ParamSpec::Type::integer, "7", 2, 64, {}, "view elevation nodes over [0, 90] degrees (level 3)"},
    {"alpha", ParamSpec::Type::integer, "11", 2, 63, {}, "light alpha nodes over [-90, 90] degrees (level 2)"},
    {"beta", ParamSpec::Type::integer, "11", 3, 63, {}, "light beta nodes, uniform in sin(beta) (level 1; odd)"},
    {"huffman", ParamSpec::Type::choice, "auto", 0, 0, {"auto", "off"}, "Huffman-code index streams where smaller (auto) or always bit-pack"},
    {"scale_bits", ParamSpec::Type::choice, "auto", 0, 0, {"auto", "8", "16"}, "scale storage; auto = 8 for LDR, 16 for HDR data (max > 1)"},
    {"noise", ParamSpec::Type::choice, "off", 0, 0, {"auto", "off"},
     "auto = cap each level's thresholds at the SSIM two noisy copies of one signal reach (noise estimated from the data); off = thresholds as given"},
};

class MlvqCodec final : public Codec {
 public:
  const char* name() const override { return "mlvq"; }
  const char* summary() const override { return "multi-level SSIM vector quantization, Huffman-coded indices, seed 003 sections 3-4"; }
  uint32_t payload_version() const override { return k_payload_version; }
  std::span<const ParamSpec> params() const override { return k_params; }

  Result<std::unique_ptr<Model>> encode(const Btf& btf, const Params& p, Context& ctx) const override {
    const BtfDesc& d = btf.desc();
    BTFC_RETURN_IF_ERROR(btf.check_finite("mlvq input"));
    if (d.channels != 3 && d.channels != 1) return unsupported("mlvq: needs 1 or 3 channels, got " + std::to_string(d.channels));
    EncodeOptions o;
    o.grid.nphi = int(p.get_int("phi"));
    o.grid.ntheta = int(p.get_int("theta"));
    o.grid.nalpha = int(p.get_int("alpha"));
    o.grid.nbeta = int(p.get_int("beta"));
    if (o.grid.nbeta % 2 == 0) return invalid_argument("mlvq: beta must be odd (a node at beta = 0), got " + std::to_string(o.grid.nbeta));
    for (int k = 1; k <= 4; ++k) o.thr[k] = o.thr_chroma[k] = p.get_real("ssim" + std::to_string(k));
    NoiseCeilings nc;
    if (p.get("noise") == "auto") {
      nc = noise_ceilings(btf, make_plan(d, o.grid), estimate_noise(btf));
      for (int k = 1; k <= 4; ++k) o.thr[k] = std::min(o.thr[k], nc.lum[k]), o.thr_chroma[k] = std::min(o.thr_chroma[k], nc.chroma[k]);
    }
    // HDR from the data range: any value above 1 (or an HDR source) needs 16-bit scales.
    float mx = 0;
    for (size_t i = 0; i < btf.size(); ++i) mx = std::max(mx, btf.data()[i]);
    const bool hdr = d.hdr || mx > 1.0f;
    const std::string sb = p.get("scale_bits");
    o.scale_bits = sb == "auto" ? (hdr ? 16 : 8) : std::stoi(sb);
    // The search kernel pays off on GPUs; on CPU devices (PoCL) OpenBLAS GEMMs are faster.
    std::string why;
    o.cl_search = ocl::use_opencl(&why);
    if (o.cl_search) {
      auto rt = ocl::Runtime::get();
      o.cl_search = rt.ok() && rt.value()->info().type.find("GPU") != std::string::npos;
    }
    const bool huffman = p.get("huffman") == "auto";
    const std::string scheme = p.get("scheme");
    std::vector<int> schemes = scheme == "best" ? std::vector<int>{1, 2, 3, 4} : std::vector<int>{std::stoi(scheme)};
    struct Candidate {
      std::unique_ptr<MlvqModel> model;
      EncodeReport rep;
      uint64_t bytes = 0;
    };
    std::vector<Candidate> cands;
    const auto t0 = std::chrono::steady_clock::now();
    if (ctx.progress) ctx.progress->start("mlvq schemes", schemes.size());
    for (int s : schemes) {
      o.scheme = s;
      Candidate c;
      BTFC_ASSIGN_OR_RETURN(Hierarchy h, encode_hierarchy(btf, o, c.rep));
      c.model = std::make_unique<MlvqModel>(d, p.canonical(), std::move(h), huffman);
      c.bytes = c.model->payload_bytes();
      cands.push_back(std::move(c));
      if (ctx.progress) ctx.progress->advance();
    }
    if (ctx.progress) ctx.progress->finish();
    // "Smallest at equal quality": among the schemes whose estimated quality is within 0.005 of
    // the best one's (the thresholds are the same for all, so they normally all are).
    double best_q = -2;
    for (const Candidate& c : cands) best_q = std::max(best_q, c.rep.mean_texel_ssim);
    size_t pick = 0;
    bool found = false;
    for (size_t i = 0; i < cands.size(); ++i)
      if (cands[i].rep.mean_texel_ssim >= best_q - 0.005 && (!found || cands[i].bytes < cands[pick].bytes)) pick = i, found = true;
    Candidate& c = cands[pick];
    ModelStats st;
    const Hierarchy& h = c.model->hierarchy();
    st.add("scheme", h.scheme);
    st.add("scale_bits", h.scale_bits);
    for (int k = 4; k >= 1; --k) {
      if (h.rgb[k].K) st.add("entries.rgb" + std::to_string(k), h.rgb[k].K);
      if (h.lum[k].K) st.add("entries.lum" + std::to_string(k), h.lum[k].K);
      if (h.chroma[k].K) st.add("entries.chroma" + std::to_string(k), h.chroma[k].K);
    }
    st.add("entries.merge", h.merge_size());
    const double raw = double(d.num_values()) * 4;
    const uint64_t plain = c.model->plain_payload_bytes();
    st.add("payload_bytes_plain", double(plain));
    st.add("payload_bytes", double(c.bytes));
    for (const auto& [name, bytes] : c.model->tensor_bytes()) st.add("bytes." + name, double(bytes));
    st.add("ratio_plain_vs_f32", raw / double(plain));
    st.add("ratio_vs_f32", raw / double(c.bytes));
    st.add("huffman_gain", double(plain) / double(c.bytes));
    for (int k = 4; k >= 1; --k) {
      st.add("noise_ceiling.lum" + std::to_string(k), nc.lum[k]);
      st.add("noise_ceiling.chroma" + std::to_string(k), nc.chroma[k]);
      st.add("threshold.lum" + std::to_string(k), o.thr[k]);
      st.add("threshold.chroma" + std::to_string(k), o.thr_chroma[k]);
    }
    st.add("mean_texel_ssim", c.rep.mean_texel_ssim);
    st.add("resample_rel_rmse", c.rep.resample_rel_rmse);
    for (const Candidate& o2 : cands) {
      const std::string s = std::to_string(o2.model->hierarchy().scheme);
      st.add("scheme" + s + ".payload_bytes", double(o2.bytes));
      st.add("scheme" + s + ".mean_texel_ssim", o2.rep.mean_texel_ssim);
      st.add("scheme" + s + ".seconds", o2.rep.seconds);
    }
    st.add("encode_seconds", std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    st.note("ssim_search", o.cl_search ? "opencl" : "cpu (OpenBLAS GEMM)");
    c.model->mutable_stats() = std::move(st);
    return std::unique_ptr<Model>(std::move(c.model));
  }

  Result<std::unique_ptr<Model>> load(const ContainerReader& rd) const override {
    if (rd.codec().payload_version > k_payload_version)
      return unsupported(rd.path() + ": mlvq payload version " + std::to_string(rd.codec().payload_version) + " is newer than this btfc supports (" +
                         std::to_string(k_payload_version) + ")");
    BTFC_ASSIGN_OR_RETURN(auto spec, parse_spec_string(rd.codec().spec));
    auto p = bind_params(spec, k_params);
    if (!p.ok()) return p.status().with_context(rd.path());
    return MlvqModel::load(rd, p.value());
  }
};

}  // namespace
}  // namespace mlvq

const Codec& mlvq_codec() {
  static const mlvq::MlvqCodec codec;
  return codec;
}

}  // namespace btfc
