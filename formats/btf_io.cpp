#include "formats/btf_io.h"

#include <filesystem>

#include "codecs/codec.h"
#include "codecs/fmf/fmf.h"
#include "core/container.h"
#include "formats/bonn/bonn_btf.h"

namespace btfc {

static bool ends_with(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

Result<Btf> read_btf(const std::string& path) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) return read_image_set(path);
  if (!std::filesystem::exists(path, ec)) return io_error(path + ": no such file or directory");
  if (is_bonn_btf(path)) {
    BTFC_ASSIGN_OR_RETURN(auto model, open_bonn_model(path));
    Btf out;
    BTFC_RETURN_IF_ERROR(model->decode_all(out).with_context(path));
    return out;
  }
  BTFC_ASSIGN_OR_RETURN(ContainerReader rd, ContainerReader::open(path));
  if (rd.codec().name == "raw") {
    BTFC_ASSIGN_OR_RETURN(Btf btf, load_raw_btf(rd));
    BTFC_RETURN_IF_ERROR(btf.check_finite(path));
    return btf;
  }
  BTFC_ASSIGN_OR_RETURN(auto model, load_model(rd));
  Btf out;
  BTFC_RETURN_IF_ERROR(model->decode_all(out).with_context(path));
  return out;
}

Result<std::unique_ptr<Model>> open_model(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) return io_error(path + ": no such file or directory");
  if (is_bonn_btf(path)) return open_bonn_model(path);
  BTFC_ASSIGN_OR_RETURN(ContainerReader rd, ContainerReader::open(path));
  return load_model(rd);
}

Status write_bonn(const Model& model, const std::string& path, bool half) {
  BTFC_ASSIGN_OR_RETURN(FmfFactorsView f, fmf_factors(model));
  return f.per_channel ? write_bonn_dfmf(model, path, half) : write_bonn_fmf(model, path, half);
}

Status write_btf(const Btf& btf, const std::string& path, ImageFormat format) {
  if (ends_with(path, ".btfc")) return save_raw_btf(btf, path);
  return write_image_set(btf, path, format);
}

}  // namespace btfc
