// The reader table (formats/reader.h).
#include "formats/reader.h"

#include <cstring>
#include <filesystem>
#include <fstream>

#include "core/container.h"
#include "formats/bonn/bonn_btf.h"
#include "formats/image_set.h"

namespace btfc {
namespace {

namespace fs = std::filesystem;

Result<Btf> decode_model(const Model& m, const std::string& path) {
  Btf out;
  BTFC_RETURN_IF_ERROR(m.decode_all(out).with_context(path));
  return out;
}

class ModelInput final : public BtfInput {
 public:
  ModelInput(const char* format, std::string path, std::unique_ptr<Model> m) : m_format(format), m_path(std::move(path)), m_model(std::move(m)) {
    m_desc = m_model->desc();
  }
  const char* format() const override { return m_format; }
  const std::string& path() const override { return m_path; }
  const BtfDesc& desc() const override { return m_desc; }
  Result<Btf> read() override {
    if (!m_model) return invalid_argument(m_path + ": the model was handed over already");
    return decode_model(*m_model, m_path);
  }
  const Model* model() const override { return m_model.get(); }
  Result<std::unique_ptr<Model>> take_model() override {
    if (!m_model) return invalid_argument(m_path + ": the model was handed over already");
    return std::move(m_model);
  }

 private:
  const char* m_format;
  std::string m_path;
  BtfDesc m_desc;
  std::unique_ptr<Model> m_model;
};

class ImageSetInput final : public BtfInput {
 public:
  explicit ImageSetInput(ImageSetPlan plan) : m_plan(std::move(plan)) {}
  const char* format() const override { return "image-set"; }
  const std::string& path() const override { return m_plan.path; }
  const BtfDesc& desc() const override { return m_plan.desc; }
  Result<Btf> read() override { return read_image_set(m_plan); }
  Result<std::unique_ptr<Model>> take_model() override {
    return invalid_argument(m_plan.path + ": an image set holds raw data, not a compressed model");
  }
  const ImageSetPlan* image_set_plan() const override { return &m_plan; }

 private:
  ImageSetPlan m_plan;
};

// A raw .btfc: the header is read at open, the data tensor by read().
class RawInput final : public BtfInput {
 public:
  explicit RawInput(ContainerReader rd) : m_rd(std::move(rd)) {}
  const char* format() const override { return "btfc"; }
  const std::string& path() const override { return m_rd.path(); }
  const BtfDesc& desc() const override { return m_rd.desc(); }
  Result<Btf> read() override {
    BTFC_ASSIGN_OR_RETURN(Btf btf, load_raw_btf(m_rd));
    BTFC_RETURN_IF_ERROR(btf.check_finite(m_rd.path()));
    return btf;
  }
  Result<std::unique_ptr<Model>> take_model() override { return load_model(m_rd); }  // names the raw container

 private:
  ContainerReader m_rd;
};

bool probe_dir(const std::string& path) {
  std::error_code ec;
  return fs::is_directory(path, ec);
}
Result<std::unique_ptr<BtfInput>> open_dir(const std::string& path) {
  BTFC_ASSIGN_OR_RETURN(ImageSetPlan plan, plan_image_set(path));
  return std::unique_ptr<BtfInput>(new ImageSetInput(std::move(plan)));
}

bool probe_bonn(const std::string& path) { return !probe_dir(path) && is_bonn_btf(path); }
Result<std::unique_ptr<BtfInput>> open_bonn(const std::string& path) {
  BTFC_ASSIGN_OR_RETURN(std::unique_ptr<Model> m, open_bonn_model(path));
  return std::unique_ptr<BtfInput>(new ModelInput("bonn", path, std::move(m)));
}

bool probe_btfc(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  char magic[4] = {};
  return f.read(magic, 4) && std::memcmp(magic, "BTFC", 4) == 0;
}
Result<std::unique_ptr<BtfInput>> open_btfc(const std::string& path) {
  BTFC_ASSIGN_OR_RETURN(ContainerReader rd, ContainerReader::open(path));
  if (rd.codec().name == "raw") return std::unique_ptr<BtfInput>(new RawInput(std::move(rd)));
  BTFC_ASSIGN_OR_RETURN(std::unique_ptr<Model> m, load_model(rd));
  return std::unique_ptr<BtfInput>(new ModelInput("btfc", path, std::move(m)));
}

const BtfReader k_readers[] = {
    {"image-set", "a directory of images in the UBO2003 or UTIA layout", &probe_dir, &open_dir},
    {"bonn", "a Bonn binary .btf (DFMF, FMF, PVF, BDI)", &probe_bonn, &open_bonn},
    {"btfc", "a .btfc container (raw data or a model of any codec)", &probe_btfc, &open_btfc},
};

}  // namespace

std::span<const BtfReader> btf_readers() { return k_readers; }

const BtfReader* find_reader(const std::string& path) {
  for (const BtfReader& r : k_readers)
    if (r.probe(path)) return &r;
  return nullptr;
}

Result<std::unique_ptr<BtfInput>> open_input(const std::string& path, const std::string& format) {
  std::error_code ec;
  if (!fs::exists(path, ec)) return io_error(path + ": no such file or directory");
  std::string names;
  for (const BtfReader& r : k_readers) {
    if (!format.empty() ? format == r.name : r.probe(path)) return r.open(path);
    names += (names.empty() ? "" : ", ") + std::string(r.name);
  }
  if (!format.empty()) return invalid_argument("--format " + format + ": unknown (readers: " + names + ")");
  // Not recognised: the container's own error says what is wrong with it (magic, truncation).
  return open_btfc(path);
}

}  // namespace btfc
