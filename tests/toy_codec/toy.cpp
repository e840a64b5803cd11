// Codec `toy` (tests/toy_codec/toy.h): encode, model, save / load.
#include "tests/toy_codec/toy.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "core/interp.h"

namespace btfc {
namespace {

constexpr uint32_t k_payload_version = 1;

const ParamSpec k_params[] = {
    {"gain", ParamSpec::Type::choice, "fit", 0, 0, {"fit", "one"}, "per-texel gain: least-squares fit, or 1 (the plain mean)"},
};

class ToyModel final : public Model {
 public:
  ToyModel(BtfDesc desc, std::string spec, std::vector<float> mean, std::vector<float> gain)
      : m_desc(std::move(desc)), m_spec(std::move(spec)), m_mean(std::move(mean)), m_gain(std::move(gain)),
        m_li(m_desc.lights), m_vi(m_desc.views) {}

  const BtfDesc& desc() const override { return m_desc; }
  const std::string& spec() const override { return m_spec; }
  const std::vector<float>& mean() const { return m_mean; }
  const std::vector<float>& gain() const { return m_gain; }

  Status decode(const DecodeRequest& req, Btf& out) const override {
    if (req.lod != 0) return unsupported(m_spec + ": this codec has no levels of detail");
    BTFC_ASSIGN_OR_RETURN(ResolvedRequest rr, resolve_request(m_desc, req));
    BTFC_RETURN_IF_ERROR(prepare_output(rr.desc, out));
    const int ch = m_desc.channels;
    for (int y = 0; y < rr.desc.height; ++y)
      for (int x = 0; x < rr.desc.width; ++x) {
        const float g = m_gain[size_t(rr.y0 + y) * size_t(m_desc.width) + size_t(rr.x0 + x)];
        float* dst = out.abrdf(size_t(x) + size_t(rr.desc.width) * size_t(y));
        for (size_t v = 0; v < rr.views.size(); ++v)
          for (size_t l = 0; l < rr.lights.size(); ++l)
            for (int c = 0; c < ch; ++c)
              dst[rr.desc.row(l, v, size_t(c))] = g * m_mean[m_desc.row(size_t(rr.lights[l]), size_t(rr.views[v]), size_t(c))];
      }
    return {};
  }
  void eval(int x, int y, int light, int view, float* out) const override {
    const float g = m_gain[size_t(y) * size_t(m_desc.width) + size_t(x)];
    for (int c = 0; c < m_desc.channels; ++c) out[c] = g * m_mean[m_desc.row(size_t(light), size_t(view), size_t(c))];
  }
  Status eval_dir(int x, int y, const Vec3& wl, const Vec3& wv, float* out) const override {
    if (x < 0 || y < 0 || x >= m_desc.width || y >= m_desc.height) return invalid_argument("texel outside the BTF");
    const DirWeights a = m_li.weights(wl), b = m_vi.weights(wv);
    std::fill(out, out + m_desc.channels, 0.0f);
    float tmp[4];
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) {
        const float w = a.weight[size_t(i)] * b.weight[size_t(j)];
        if (w == 0) continue;
        eval(x, y, a.index[size_t(i)], b.index[size_t(j)], tmp);
        for (int c = 0; c < m_desc.channels; ++c) out[c] += w * tmp[c];
      }
    return {};
  }
  Result<std::vector<Tensor>> gpu_tensors() const override { return tensors(); }
  Status save(ContainerWriter& w) const override {
    for (Tensor& t : tensors()) w.add_tensor(std::move(t));
    return {};
  }
  uint64_t payload_bytes() const override { return (m_mean.size() + m_gain.size()) * sizeof(float); }
  ModelStats stats() const override {
    ModelStats s;
    s.add("basis_values", double(m_mean.size()));
    s.add("texels", double(m_gain.size()));
    return s;
  }

 private:
  std::vector<Tensor> tensors() const {
    return {Tensor::from_f32("mean", {uint64_t(m_mean.size())}, m_mean.data()),
            Tensor::from_f32("gain", {uint64_t(m_desc.height), uint64_t(m_desc.width)}, m_gain.data())};
  }
  BtfDesc m_desc;
  std::string m_spec;
  std::vector<float> m_mean, m_gain;
  DirectionInterpolator m_li, m_vi;
};

class ToyCodec final : public Codec {
 public:
  const char* name() const override { return "toy"; }
  const char* summary() const override { return "test-only rank-1 mean-ABRDF codec (tests/toy_codec)"; }
  uint32_t payload_version() const override { return k_payload_version; }
  std::span<const ParamSpec> params() const override { return k_params; }

  Result<std::unique_ptr<Model>> encode(const Btf& btf, const Params& p, Context& ctx) const override {
    const BtfDesc& d = btf.desc();
    const size_t rows = d.abrdf_size(), n = d.num_texels();
    std::vector<double> acc(rows, 0.0);
    for (size_t t = 0; t < n; ++t) {
      const float* a = btf.abrdf(t);
      for (size_t r = 0; r < rows; ++r) acc[r] += a[r];
    }
    std::vector<float> mean(rows);
    double mm = 0;
    for (size_t r = 0; r < rows; ++r) mean[r] = float(acc[r] / double(n)), mm += double(mean[r]) * mean[r];
    std::vector<float> gain(n, 1.0f);
    if (p.get("gain") == "fit")
      for (size_t t = 0; t < n; ++t) {
        const float* a = btf.abrdf(t);
        double dot = 0;
        for (size_t r = 0; r < rows; ++r) dot += double(a[r]) * mean[r];
        gain[t] = mm > 0 ? float(dot / mm) : 0.0f;
      }
    return std::unique_ptr<Model>(new ToyModel(d, p.canonical(), std::move(mean), std::move(gain)));
  }

  Result<std::unique_ptr<Model>> load(const ContainerReader& rd) const override {
    if (rd.codec().payload_version > k_payload_version)
      return unsupported(rd.path() + ": toy payload version " + std::to_string(rd.codec().payload_version) + " is newer than supported");
    BTFC_ASSIGN_OR_RETURN(auto spec, parse_spec_string(rd.codec().spec));
    if (spec.codec != "toy") return corrupt_data(rd.path() + ": codec spec '" + rd.codec().spec + "' is not toy");
    BTFC_ASSIGN_OR_RETURN(Params p, bind_params(spec, k_params));
    const BtfDesc& d = rd.desc();
    BTFC_ASSIGN_OR_RETURN(std::vector<float> mean, rd.read_floats("mean", {uint64_t(d.abrdf_size())}));
    BTFC_ASSIGN_OR_RETURN(std::vector<float> gain, rd.read_floats("gain", {uint64_t(d.height), uint64_t(d.width)}));
    for (float v : mean)
      if (!std::isfinite(v)) return corrupt_data(rd.path() + ": toy mean holds NaN or Inf");
    for (float v : gain)
      if (!std::isfinite(v)) return corrupt_data(rd.path() + ": toy gain holds NaN or Inf");
    return std::unique_ptr<Model>(new ToyModel(d, p.canonical(), std::move(mean), std::move(gain)));
  }
};

}  // namespace

const Codec& toy_codec() {
  static const ToyCodec codec;
  return codec;
}

}  // namespace btfc
