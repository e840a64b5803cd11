// Codec-independent helpers: spec resolution, model files, decode requests.
#include <algorithm>
#include <sstream>

#include "codecs/codec.h"
#include "core/cl_runtime.h"

namespace btfc {

Result<std::pair<const Codec*, Params>> resolve_spec(const std::string& spec) {
  BTFC_ASSIGN_OR_RETURN(SpecString s, parse_spec_string(spec));
  const Codec* codec = find_codec(s.codec);
  if (!codec) {
    std::string names;
    for (const Codec* c : all_codecs()) names += (names.empty() ? "" : ", ") + std::string(c->name());
    return invalid_argument("unknown codec '" + s.codec + "' (registered: " + names + ")");
  }
  BTFC_ASSIGN_OR_RETURN(Params p, bind_params(s, codec->params()));
  return std::make_pair(codec, std::move(p));
}

static std::string stats_text(const ModelStats& st) {
  std::ostringstream os;
  os.precision(9);
  for (const auto& [k, v] : st.numbers) os << k << " = " << v << "\n";
  for (const auto& [k, v] : st.notes) os << k << " = " << v << "\n";
  os << "device = " << ocl::device_summary() << "\n";
  return os.str();
}

Result<uint64_t> model_file_bytes(const Model& model, const Codec& codec) {
  ContainerWriter w;
  w.set_desc(model.desc());
  w.set_codec({codec.name(), codec.payload_version(), model.spec(), btfc_version()});
  BTFC_RETURN_IF_ERROR(model.save(w));
  w.set_stats(stats_text(model.stats()));
  return w.file_size();
}

Status save_model(const Model& model, const Codec& codec, const std::string& path) {
  ContainerWriter w;
  w.set_desc(model.desc());
  w.set_codec({codec.name(), codec.payload_version(), model.spec(), btfc_version()});
  BTFC_RETURN_IF_ERROR(model.save(w));
  w.set_stats(stats_text(model.stats()));
  return w.write(path);
}

Result<std::unique_ptr<Model>> load_model(const ContainerReader& reader) {
  const std::string& name = reader.codec().name;
  if (name == "raw") return invalid_argument(reader.path() + ": holds an uncompressed BTF, not a model");
  const Codec* codec = find_codec(name);
  if (!codec) return unsupported(reader.path() + ": unknown codec '" + name + "'");
  // Loaders hold every tensor in memory as float (half payloads double), so the model needs
  // about this much; refuse before any codec allocates (core/limits.h).
  uint64_t need = 0;
  for (const TensorInfo& t : reader.tensors()) {
    if (t.dtype != DType::zq) {
      need += t.size / dtype_size(t.dtype) * std::max<uint64_t>(4, dtype_size(t.dtype));
      continue;
    }
    // A zq tensor decodes to floats (plus its integers while decoding): its declared element
    // count, saturating, so a hostile shape is refused here before anything is allocated.
    uint64_t n = 8;
    for (uint64_t d : t.shape)
      if (__builtin_mul_overflow(n, d, &n)) n = UINT64_MAX / 2;
    need = n > UINT64_MAX / 2 - need ? UINT64_MAX / 2 : need + n + t.size;
  }
  BTFC_RETURN_IF_ERROR(check_memory(size_t(need), reader.path() + ": loading the " + name + " model"));
  return codec->load(reader);
}

Status check_eval_queries(const BtfDesc& d, std::span<const EvalQuery> q) {
  for (const EvalQuery& e : q)
    if (e.x < 0 || e.y < 0 || e.x >= d.width || e.y >= d.height || (e.light >= 0) != (e.view >= 0) ||
        (e.light >= 0 && (size_t(e.light) >= d.num_lights() || size_t(e.view) >= d.num_views())))
      return invalid_argument("eval query (" + std::to_string(e.x) + ", " + std::to_string(e.y) + ", light " +
                              std::to_string(e.light) + ", view " + std::to_string(e.view) + ") is outside the BTF");
  return {};
}

Status Model::eval_batch(std::span<const EvalQuery> q, float* out) const {
  const size_t nc = size_t(desc().channels);
  BTFC_RETURN_IF_ERROR(check_eval_queries(desc(), q));  // first, so the parallel loop cannot fail
#pragma omp parallel for schedule(static)
  for (size_t i = 0; i < q.size(); ++i) {
    if (q[i].light >= 0) eval(q[i].x, q[i].y, q[i].light, q[i].view, out + i * nc);
    else (void)eval_dir(q[i].x, q[i].y, q[i].wl, q[i].wv, out + i * nc);
  }
  return {};
}

Status prepare_output(const BtfDesc& desc, Btf& out) {
  if (out.size() == desc.num_values() && out.size() > 0) {
    BTFC_RETURN_IF_ERROR(desc.validate());
    out.reshape(desc);
    return {};
  }
  BTFC_ASSIGN_OR_RETURN(out, Btf::create(desc));
  return {};
}

Result<ResolvedRequest> resolve_request(const BtfDesc& src, const DecodeRequest& req) {
  ResolvedRequest r;
  r.x0 = req.x0;
  r.y0 = req.y0;
  const int w = req.width < 0 ? src.width - req.x0 : req.width;
  const int h = req.height < 0 ? src.height - req.y0 : req.height;
  if (req.x0 < 0 || req.y0 < 0 || w <= 0 || h <= 0 || req.x0 + w > src.width || req.y0 + h > src.height) {
    std::ostringstream os;
    os << "region (" << req.x0 << ", " << req.y0 << ") size " << w << "x" << h << " is outside the " << src.width << "x"
       << src.height << " texels";
    return invalid_argument(os.str());
  }
  auto pick = [](const DirectionSet& set, const std::vector<int>& want, std::vector<int>& idx, DirectionSet& out,
                 const char* what) -> Status {
    out.dirs.clear();
    idx.clear();
    if (want.empty()) {
      for (size_t i = 0; i < set.size(); ++i) idx.push_back(int(i));
      out = set;
      return {};
    }
    for (int i : want) {
      if (i < 0 || size_t(i) >= set.size())
        return invalid_argument(std::string(what) + " index " + std::to_string(i) + " outside [0, " + std::to_string(set.size()) + ")");
      idx.push_back(i);
      out.dirs.push_back(set.dirs[size_t(i)]);
    }
    out.identify();
    return {};
  };
  r.desc = src;
  r.desc.width = w;
  r.desc.height = h;
  BTFC_RETURN_IF_ERROR(pick(src.lights, req.lights, r.lights, r.desc.lights, "light"));
  BTFC_RETURN_IF_ERROR(pick(src.views, req.views, r.views, r.desc.views, "view"));
  return r;
}

}  // namespace btfc
