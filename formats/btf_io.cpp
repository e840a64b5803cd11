#include "formats/btf_io.h"

#include <filesystem>

#include "codecs/codec.h"
#include "codecs/fmf/fmf.h"
#include "core/container.h"
#include "formats/bonn/bonn_btf.h"
#include "formats/reader.h"

namespace btfc {

static bool ends_with(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

Result<Btf> read_btf(const std::string& path) {
  BTFC_ASSIGN_OR_RETURN(std::unique_ptr<BtfInput> in, open_input(path));
  return in->read();
}

Result<std::unique_ptr<Model>> open_model(const std::string& path) {
  BTFC_ASSIGN_OR_RETURN(std::unique_ptr<BtfInput> in, open_input(path));
  return in->take_model();
}

Status write_bonn(const Model& model, const std::string& path, bool half) {
  BTFC_ASSIGN_OR_RETURN(FmfFactorsView f, fmf_factors(model));
  return f.per_channel ? write_bonn_dfmf(model, path, half) : write_bonn_fmf(model, path, half);
}

namespace {

std::string bonn_spec(const std::string& spec, std::string* note) {
  auto s = parse_spec_string(spec);
  if (!s.ok() || s->codec != "fmf") return spec;
  bool dfmf = false, offset = false;
  for (const auto& [k, v] : s->values) dfmf |= k == "color" && v == "dfmf", offset |= k == "offset";
  if (!dfmf || offset) return spec;
  const std::string out = spec + ":offset=1e-5";
  if (note) *note = "a Bonn DFMF file holds colour model 11's luminance offset: using " + out;
  return out;
}

Status write_bonn_model(const Model& model, const std::string& path) {
  BTFC_ASSIGN_OR_RETURN(FmfFactorsView f, fmf_factors(model));
  return write_bonn(model, path, f.half);
}

Status write_btfc_model(const Model& model, const std::string& path) {
  auto spec = parse_spec_string(model.spec());
  const Codec* codec = spec.ok() ? find_codec(spec->codec) : nullptr;
  if (!codec) return unsupported(path + ": the model's codec '" + model.spec() + "' is not registered");
  return save_model(model, *codec, path);
}

const ModelWriter k_model_writers[] = {
    {"btfc", ".btfc", nullptr, &write_btfc_model},
    {"bonn", ".btf", &bonn_spec, &write_bonn_model},
};

}  // namespace

std::span<const ModelWriter> model_writers() { return k_model_writers; }

const ModelWriter* model_writer_for(const std::string& path) {
  for (const ModelWriter& w : k_model_writers)
    if (ends_with(path, w.extension)) return &w;
  return nullptr;
}

std::string spec_for_output(const std::string& spec, const std::string& path, std::string* note) {
  const ModelWriter* w = model_writer_for(path);
  return w && w->adapt_spec ? w->adapt_spec(spec, note) : spec;
}

Status write_model(const Model& model, const std::string& path) {
  const ModelWriter* w = model_writer_for(path);
  if (!w) {
    std::string known;
    for (const ModelWriter& m : k_model_writers) known += (known.empty() ? "" : ", ") + std::string(m.extension);
    return invalid_argument(path + ": a model is written as " + known);
  }
  return w->write(model, path);
}

Status write_btf(const Btf& btf, const std::string& path, ImageFormat format) {
  if (ends_with(path, ".btfc")) return save_raw_btf(btf, path);
  return write_image_set(btf, path, format);
}

}  // namespace btfc
