// Bonn .btf dispatch: signature -> common header -> format body -> trailing-bytes rule
// (formats.md 2.2; docs/FORMAT.md "Bonn .btf files"). See bonn_btf.h for the contracts.
#include "formats/bonn/bonn_btf.h"

#include <cstdio>
#include <cstring>

#include "codecs/fmf/fmf.h"
#include "formats/bonn/bdi_work.h"
#include "formats/bonn/bonn_io.h"

namespace btfc {
namespace {

using bonn::ByteSource;

// Parses the whole file; with `load` also builds the model.
Result<std::unique_ptr<Model>> parse(const std::string& path, BonnInfo& info, bool load) {
  BTFC_ASSIGN_OR_RETURN(ByteSource src, ByteSource::open(path));
  info = BonnInfo{};
  info.path = path;
  info.file_size = src.size();
  uint8_t head[10] = {0};
  const size_t n = size_t(std::min<uint64_t>(10, src.size()));
  BTFC_RETURN_IF_ERROR(src.read_at(0, head, n, "signature"));
  info.signature = bonn::match_signature(head, n);
  if (info.signature.empty()) {
    if (n == 10 && std::memcmp(head, k_bdi_incomplete, 10) == 0)
      return corrupt_data(path + ": incomplete working file from an interrupted btfc run (its completion signature was never "
                                 "written); not trusted");
    std::string shown;
    for (size_t i = 0; i < n; ++i) shown += (head[i] >= 32 && head[i] < 127) ? char(head[i]) : '.';
    return corrupt_data(path + ": not a Bonn .btf file (signature '" + shown +
                        "' is none of !DFMF08FCR, !FMF12FCER, !FMF06FC[R], !PVF06FC[R], !BDIF06R2!)");
  }
  BTFC_RETURN_IF_ERROR(src.skip(info.signature.size(), "signature"));
  const char k = info.signature[1];
  info.kind = k == 'D' ? BonnKind::dfmf : k == 'F' ? BonnKind::fmf : k == 'P' ? BonnKind::pvf : BonnKind::bdi;
  if (info.kind == BonnKind::pvf && src.remaining() >= 4) {
    int32_t magic = 0;
    BTFC_RETURN_IF_ERROR(src.read_at(src.pos(), &magic, 4, "PVF magic"));
    if (magic == 301074) return unsupported(path + ": legacy PVF (magic 301074) is not supported");
  }
  BTFC_RETURN_IF_ERROR(bonn::read_meta(src, info.meta));
  BTFC_RETURN_IF_ERROR(bonn::read_sampling(src, info));
  std::unique_ptr<Model> model;
  if (info.kind == BonnKind::bdi) {
    BTFC_ASSIGN_OR_RETURN(model, bonn::read_bdi(src, info, load));
  } else {
    BTFC_RETURN_IF_ERROR(bonn::read_size(src, info));
    if (info.signature.back() == 'R') BTFC_RETURN_IF_ERROR(bonn::read_rotations(src, info));
    BTFC_RETURN_IF_ERROR(bonn::finish_desc(src, info));
    if (info.kind == BonnKind::pvf) {
      BTFC_ASSIGN_OR_RETURN(model, bonn::read_pvf(src, info, load));
    } else {
      bonn::FmfBody body;
      std::vector<FmfFactors> blocks;
      std::vector<FmfFactors>* dst = load ? &blocks : nullptr;
      BTFC_RETURN_IF_ERROR(info.kind == BonnKind::dfmf ? bonn::read_dfmf_body(src, info, body, dst)
                                                       : bonn::read_fmf_body(src, info, body, dst));
      if (src.remaining() != 0)
        return src.corrupt(std::to_string(src.remaining()) + " trailing bytes after the " + bonn_kind_name(info.kind) + " data at offset " +
                           std::to_string(src.pos()));
      if (load) {
        auto m = make_fmf_model(info.desc, body.color_model, std::move(blocks), body.color_mean, body.color_transform, body.half);
        if (!m.ok()) return m.status().with_context(path);
        model = std::move(m).value();
      }
    }
  }
  if (src.remaining() != 0)
    return src.corrupt(std::to_string(src.remaining()) + " trailing bytes after the " + bonn_kind_name(info.kind) + " data at offset " +
                       std::to_string(src.pos()));
  return model;
}

}  // namespace

bool is_bonn_btf(const std::string& path) {
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) return false;
  uint8_t head[10];
  const size_t n = std::fread(head, 1, sizeof head, f);
  std::fclose(f);
  // An unfinished btfc working file (bdi_work.h) counts too, so opening it names the problem.
  return !bonn::match_signature(head, n).empty() || (n == 10 && std::memcmp(head, k_bdi_incomplete, 10) == 0);
}

Result<BonnInfo> read_bonn_info(const std::string& path) {
  BonnInfo info;
  auto r = parse(path, info, false);
  if (!r.ok()) return r.status();
  return info;
}

Result<std::unique_ptr<Model>> open_bonn_model(const std::string& path, BonnInfo* info_out) {
  BonnInfo info;
  BTFC_ASSIGN_OR_RETURN(std::unique_ptr<Model> m, parse(path, info, true));
  if (info_out) *info_out = std::move(info);
  return m;
}

}  // namespace btfc
