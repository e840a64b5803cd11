// mlvq codec: parameters, the scheme choice (`scheme=best`), HDR detection, loading.
// See mlvq.h for the paper and the pipeline.
#include "codecs/mlvq/mlvq.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>

#include "codecs/mlvq/mlvq_internal.h"
#include "core/cl_runtime.h"

namespace btfc {
namespace mlvq {

namespace {

const ParamSpec k_params[] = {
    {"scheme", ParamSpec::Type::choice, "4", 0, 0, {"best", "1", "2", "3", "4"},
     "level at which luminance and chromaticity split (paper Fig. 2); best = encode with all four, keep the smallest"},
    {"ssim4", ParamSpec::Type::real, "0.95", 0, 1, {}, "SSIM threshold for reusing a 4D codebook entry (per texel)"},
    {"ssim3", ParamSpec::Type::real, "0.93", 0, 1, {}, "SSIM threshold for 3D entries (per view azimuth / view group)"},
    {"ssim2", ParamSpec::Type::real, "0.9", 0, 1, {}, "SSIM threshold for 2D entries (per view elevation / view)"},
    {"ssim1", ParamSpec::Type::real, "0.9", 0, 1, {}, "SSIM threshold for 1D entries (per light alpha / light group)", true},
    {"chroma", ParamSpec::Type::real, "3", 0, 100, {},
     "chromaticity thresholds = 1 - chroma (1 - luminance threshold) per level"},
    {"layout", ParamSpec::Type::choice, "auto", 0, 0, {"auto", "measured", "grid"},
     "measured = the hierarchy over the measured directions (groups of views / lights, no resampling); grid = the paper's resampled 4D "
     "grid (phi, theta, alpha, beta); auto = grid when any of those four is given, else measured"},
    {"phi", ParamSpec::Type::integer, "16", 1, 64, {}, "view azimuth nodes (level 4)"},
    {"theta", ParamSpec::Type::integer, "7", 2, 64, {}, "view elevation nodes over [0, 90] degrees (level 3)"},
    {"alpha", ParamSpec::Type::integer, "11", 2, 63, {}, "light alpha nodes over [-90, 90] degrees (level 2)"},
    {"beta", ParamSpec::Type::integer, "11", 3, 63, {}, "light beta nodes, uniform in sin(beta) (level 1; odd)"},
    {"value_bits", ParamSpec::Type::integer, "8", 0, 16, {},
     "level-1 values in steps of 2^-bits, zstd-coded (zq); 0 = half floats (the paper's storage)"},
    {"huffman", ParamSpec::Type::choice, "auto", 0, 0, {"auto", "off"}, "Huffman-code index streams where smaller (auto) or always bit-pack"},
    {"scale_bits", ParamSpec::Type::choice, "auto", 0, 0, {"auto", "8", "10", "12", "16"},
     "log-uniform scale codes (zstd-coded where smaller); auto = 8 for LDR, 10 for HDR data (max > 1)"},
    {"noise", ParamSpec::Type::choice, "auto", 0, 0, {"auto", "off"},
     "auto = cap each level's thresholds at the SSIM two noisy copies of one signal reach (noise estimated from the data; never more "
     "than 0.2 below the given threshold); off = thresholds as given"},
    {"min_ratio", ParamSpec::Type::real, "30", 0, 1e9, {},
     "if the payload is larger than float32 raw / min_ratio, relax all thresholds (1 - t -> 1.6 (1 - t)) and encode again, at most 4 "
     "times; 0 = off"},
};

class MlvqCodec final : public Codec {
 public:
  const char* name() const override { return "mlvq"; }
  const char* summary() const override { return "multi-level SSIM vector quantization, Huffman-coded indices, seed 003 sections 3-4"; }
  uint32_t payload_version() const override { return k_payload_version; }
  std::span<const ParamSpec> params() const override { return k_params; }
  const char* no_budget_search() const override {
    return "every probe of a search is a whole vector-quantization encode (about a minute for 64 x 64 texels x 81 x 81 "
           "directions), so a search would take many minutes; use mlvq:min_ratio=R instead (the thresholds are relaxed, "
           "up to 4 times, while the payload exceeds float32 raw / R) or set the ssim1..ssim4 thresholds";
  }

  // The quality knob (ssim1) moves one level's threshold of four; the other levels' defaults, the
  // noise cap, the ratio floor (which relaxes every threshold again) and the 8-bit values and
  // scales cap what it reaches (a clean one-texel BTF: 28.8 dB at most). A quality target that
  // the knob misses is searched again with the other levels strict, then stricter with finer bits
  // (the same BTF: 40 dB; a noisy 9 x 7 one: 52 dB).
  std::vector<std::string> quality_variants() const override {
    return {"ssim2=0.99:ssim3=0.99:ssim4=0.99:noise=off:min_ratio=0",
            "ssim2=0.999:ssim3=0.999:ssim4=0.999:noise=off:min_ratio=0:value_bits=12:scale_bits=12"};
  }

  Result<std::unique_ptr<Model>> encode(const Btf& btf, const Params& p, Context& ctx) const override {
    const BtfDesc& d = btf.desc();
    BTFC_RETURN_IF_ERROR(btf.check_finite("mlvq input"));
    if (d.channels != 3 && d.channels != 1) return unsupported("mlvq: needs 1 or 3 channels, got " + std::to_string(d.channels));
    EncodeOptions o;
    o.grid.nphi = int(p.get_int("phi"));
    o.grid.ntheta = int(p.get_int("theta"));
    o.grid.nalpha = int(p.get_int("alpha"));
    o.grid.nbeta = int(p.get_int("beta"));
    const bool grid_given = p.was_set("phi") || p.was_set("theta") || p.was_set("alpha") || p.was_set("beta");
    if (p.get("layout") == "measured" || (p.get("layout") == "auto" && !grid_given)) o.grid = measured_grid(d);
    else if (o.grid.nbeta % 2 == 0) return invalid_argument("mlvq: beta must be odd (a node at beta = 0), got " + std::to_string(o.grid.nbeta));
    for (int k = 1; k <= 4; ++k) {
      o.thr[k] = p.get_real("ssim" + std::to_string(k));
      o.thr_chroma[k] = 1 - p.get_real("chroma") * (1 - o.thr[k]);
    }
    NoiseCeilings nc;
    if (p.get("noise") == "auto") {
      nc = noise_ceilings(btf, make_plan(d, o.grid), estimate_noise(btf));
      // The floor (0.2 below the given threshold) bounds what a misestimate can do: the image-domain
      // estimator counts texel-scale contrast as noise (see mlvq.h).
      for (int k = 1; k <= 4; ++k)
        o.thr[k] = std::min(o.thr[k], std::max(nc.lum[k], o.thr[k] - 0.2)),
        o.thr_chroma[k] = std::min(o.thr_chroma[k], std::max(nc.chroma[k], o.thr_chroma[k] - 0.2));
    }
    // HDR from the data range: any value above 1 (or an HDR source) needs 16-bit scales.
    // 10-bit scales cover 1e6 within a stream (codebook.cpp); when the texels' peaks alone span
    // more than 1e4, the texel scales need the 16-bit (unclipped) codes.
    float mx = 0, pmin = 0;
    {
      const size_t n = d.num_texels(), a = d.abrdf_size();
      for (size_t t = 0; t < n; ++t) {
        const float* v = btf.abrdf(t);
        const float pk = *std::max_element(v, v + a);
        mx = std::max(mx, pk);
        if (pk > 0) pmin = pmin == 0 ? pk : std::min(pmin, pk);
      }
    }
    const bool hdr = d.hdr || mx > 1.0f;
    const std::string sb = p.get("scale_bits");
    o.scale_bits = sb == "auto" ? (!hdr ? 8 : (pmin > 0 && mx / pmin > 1e4f) ? 16 : 10) : std::stoi(sb);
    // The search kernel pays off on GPUs; on CPU devices (PoCL) OpenBLAS GEMMs are faster.
    std::string why;
    o.cl_search = ocl::use_opencl(&why);
    if (o.cl_search) {
      auto rt = ocl::Runtime::get();
      o.cl_search = rt.ok() && rt.value()->info().type == "gpu";
    }
    o.value_bits = int(p.get_int("value_bits"));
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
    // The ratio floor: thresholds that keep too much (very noisy data, or thresholds set high)
    // are relaxed geometrically in 1 - t and the whole encode repeated, so the default never
    // gives a tiny ratio (issue 22: >= 30 : 1 on any full BTF); each retry is faster than the
    // one before (fewer entries).
    const double min_ratio = p.get_real("min_ratio"), raw_bytes = double(d.num_values()) * 4;
    int relaxed = 0;
    for (;;) {
      for (int s : schemes) {
        o.scheme = s;
        Candidate c;
        BTFC_ASSIGN_OR_RETURN(Hierarchy h, encode_hierarchy(btf, o, c.rep));
        // Finite input can still overflow the level-1 values (luminance sums of values near
        // 3.4e38), which the stored tensors cannot hold (MlvqModel::tensors): an error, not a model.
        for (const std::vector<float>* v : {&h.lum[1].values, &h.chroma[1].values})
          if (std::any_of(v->begin(), v->end(), [](float x) { return !std::isfinite(x); })) {
            char top[32];
            std::snprintf(top, sizeof top, "%.3g", double(mx));
            return unsupported(std::string("mlvq: the codebook values overflow float (input values up to ") + top +
                               ", near the largest float 3.4e38): scale the BTF down");
          }
        c.model = std::make_unique<MlvqModel>(d, p.canonical(), std::move(h), huffman);
        c.bytes = c.model->payload_bytes();
        cands.push_back(std::move(c));
        if (ctx.progress) ctx.progress->advance();
      }
      uint64_t smallest = UINT64_MAX;
      for (const Candidate& c : cands) smallest = std::min(smallest, c.bytes);
      if (min_ratio <= 0 || relaxed >= 4 || double(smallest) * min_ratio <= raw_bytes) break;
      cands.clear();
      ++relaxed;
      for (int k = 1; k <= 4; ++k) o.thr[k] = 1 - 1.6 * (1 - o.thr[k]), o.thr_chroma[k] = 1 - 1.6 * (1 - o.thr_chroma[k]);
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
    const uint64_t plain = c.model->plain_payload_bytes();
    st.add("payload_bytes_plain", double(plain));
    st.add("payload_bytes", double(c.bytes));
    for (const auto& [name, bytes] : c.model->tensor_bytes()) st.add("bytes." + name, double(bytes));
    st.add("huffman_gain", double(plain) / double(c.bytes));
    for (int k = 4; k >= 1; --k) {
      st.add("noise_ceiling.lum" + std::to_string(k), nc.lum[k]);
      st.add("noise_ceiling.chroma" + std::to_string(k), nc.chroma[k]);
      st.add("threshold.lum" + std::to_string(k), o.thr[k]);
      st.add("threshold.chroma" + std::to_string(k), o.thr_chroma[k]);
    }
    for (int k = 4; k >= 1; --k)
      for (int q = 0; q < 3; ++q)
        if (c.rep.pass_seconds[q][k] > 0) st.add(std::string("seconds.") + (q == 0 ? "rgb" : q == 1 ? "lum" : "chroma") + std::to_string(k), c.rep.pass_seconds[q][k]);
    st.add("seconds.refit", c.rep.refit_seconds);
    st.add("relaxed", relaxed);
    st.add("layout_measured", h.grid.measured() ? 1 : 0);
    st.add("value_bits", h.value_bits);
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
