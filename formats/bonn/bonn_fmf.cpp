// Bonn DFMF (!DFMF08FCR) and FMF (!FMF12FCER, !FMF06FC[R]) bodies: reading into fmf factors and
// writing fmf models (formats.md 2.2: BTFLIB read_ubo_dfmf.m, read_ubo_fmf.m, write_ubo_dfmf.m,
// write_ubo_fmf.m; layouts pinned in docs/FORMAT.md "Bonn .btf files").
#include <algorithm>
#include <cstring>

#include "codecs/fmf/fmf.h"
#include "core/params.h"
#include "formats/bonn/bonn_io.h"

namespace btfc {
namespace bonn {
namespace {

const char* scalar_name(int ss) { return ss == 2 ? "half" : ss == 4 ? "float" : "double"; }

// One stored factorization: S [C], U [num_rows][C], SxV [num_cols][C]. Sizes are checked against
// the file (overflow-safe) before the consistency checks and before any allocation.
Status read_factors(ByteSource& src, const std::string& f, int ss, uint32_t C, uint32_t num_rows, uint32_t num_cols,
                    uint64_t want_rows, const std::string& rows_what, uint64_t want_cols, const std::string& name,
                    std::vector<FmfFactors>* blocks) {
  if (C == 0) return src.corrupt(f + " num_components is 0");
  uint64_t s_bytes = uint64_t(C) * uint64_t(ss), u_bytes, x_bytes;
  if (!mul_ok(uint64_t(num_rows) * C, uint64_t(ss), u_bytes) || u_bytes > src.remaining())
    return src.corrupt(f + " U (num_rows " + std::to_string(num_rows) + " x " + std::to_string(C) + " " + scalar_name(ss) +
                       ") exceeds the file (" + std::to_string(src.remaining()) + " bytes left at offset " + std::to_string(src.pos()) + ")");
  if (!mul_ok(uint64_t(num_cols) * C, uint64_t(ss), x_bytes) || x_bytes > src.remaining())
    return src.corrupt(f + " num_cols " + std::to_string(num_cols) + " (SxV " + std::to_string(num_cols) + " x " + std::to_string(C) +
                       " " + scalar_name(ss) + ") exceeds the file (" + std::to_string(src.remaining()) + " bytes left at offset " +
                       std::to_string(src.pos()) + ")");
  if (s_bytes + u_bytes + x_bytes > src.remaining())
    return src.corrupt(f + " S, U and SxV (" + std::to_string(s_bytes + u_bytes + x_bytes) + " bytes) exceed the file (" +
                       std::to_string(src.remaining()) + " bytes left at offset " + std::to_string(src.pos()) + ")");
  if (num_rows != want_rows)
    return src.corrupt(f + " num_rows " + std::to_string(num_rows) + " disagrees with " + rows_what + " = " + std::to_string(want_rows));
  if (num_cols != want_cols)
    return src.corrupt(f + " num_cols " + std::to_string(num_cols) + " disagrees with width x height = " + std::to_string(want_cols));
  if (!blocks) return src.skip(s_bytes + u_bytes + x_bytes, f + " data");
  FmfFactors b;
  b.name = name;
  b.C = int(C);
  b.S.resize(C);
  b.U.resize(size_t(num_rows) * C);
  b.SxV.resize(size_t(num_cols) * C);
  BTFC_RETURN_IF_ERROR(src.scalars(b.S.data(), C, ss, f + " S"));
  BTFC_RETURN_IF_ERROR(src.scalars(b.U.data(), uint64_t(num_rows) * C, ss, f + " U"));
  BTFC_RETURN_IF_ERROR(src.scalars(b.SxV.data(), uint64_t(num_cols) * C, ss, f + " SxV"));
  blocks->push_back(std::move(b));
  return {};
}

Status check_scalar_size(const ByteSource& src, const std::string& f, uint8_t ss) {
  if (ss == 2 || ss == 4 || ss == 8) return {};
  return src.corrupt(f + " scalar_size " + std::to_string(ss) + " (2, 4 or 8 expected)");
}

}  // namespace

Status read_dfmf_body(ByteSource& src, BonnInfo& info, FmfBody& body, std::vector<FmfFactors>* blocks) {
  uint32_t cmax = 0;
  int32_t cm = 0;
  BTFC_RETURN_IF_ERROR(src.u32(cmax, "DFMF num_components_max"));
  BTFC_RETURN_IF_ERROR(src.i32(cm, "DFMF color_model"));
  BTFC_RETURN_IF_ERROR(src.bytes(body.color_mean, 12, "DFMF color_mean"));
  BTFC_RETURN_IF_ERROR(src.bytes(body.color_transform, 36, "DFMF color_transform"));
  body.color_model = info.color_model = cm;
  body.half = true;
  const BtfDesc& d = info.desc;
  static const char* names[3] = {"y", "u", "v"};
  for (int c = 0; c < d.channels; ++c) {
    const std::string f = "DFMF channel " + std::to_string(c);
    uint8_t ss = 0;
    uint32_t C = 0, nr = 0, nc = 0;
    BTFC_RETURN_IF_ERROR(src.u8(ss, f + " scalar_size"));
    BTFC_RETURN_IF_ERROR(check_scalar_size(src, f, ss));
    BTFC_RETURN_IF_ERROR(src.u32(C, f + " num_components"));
    BTFC_RETURN_IF_ERROR(src.u32(nr, f + " num_rows"));
    BTFC_RETURN_IF_ERROR(src.u32(nc, f + " num_cols"));
    if (C > cmax)
      return src.corrupt(f + " num_components " + std::to_string(C) + " exceeds num_components_max " + std::to_string(cmax));
    BTFC_RETURN_IF_ERROR(read_factors(src, f, ss, C, nr, nc, d.num_images(), "num_lights x num_views", d.num_texels(),
                                      c < 3 ? std::string(names[c]) : std::string("c") + std::to_string(c), blocks));
    info.scalar_sizes.push_back(ss);
    info.components.push_back(int(C));
    body.half = body.half && ss == 2;
  }
  return {};
}

Status read_fmf_body(ByteSource& src, BonnInfo& info, FmfBody& body, std::vector<FmfFactors>* blocks) {
  uint32_t drr = 0;
  if (info.signature == "!FMF12FCER") {
    uint8_t hv = 0;
    BTFC_RETURN_IF_ERROR(src.u8(hv, "FMF header_version"));
    if (hv >= 3) return unsupported(src.path() + ": FMF header_version " + std::to_string(hv) + " (0-2 supported)");
    if (hv >= 1) BTFC_RETURN_IF_ERROR(src.u32(drr, "FMF dynamic_range_reduction_method"));
    if (hv >= 2) {
      uint32_t hw = 0, hh = 0;
      BTFC_RETURN_IF_ERROR(src.u32(hw, "FMF heightmap width"));
      BTFC_RETURN_IF_ERROR(src.u32(hh, "FMF heightmap height"));
      // The height map is not part of the BTF; it is validated and skipped.
      BTFC_RETURN_IF_ERROR(src.skip(uint64_t(hw) * hh * 2, "FMF heightmap (" + std::to_string(hw) + " x " + std::to_string(hh) + " half)"));
    }
  }
  body.color_model = info.color_model = drr ? 12 : 0;
  uint32_t C = 0, C2 = 0, nr = 0, nc = 0;
  uint8_t ss = 0;
  BTFC_RETURN_IF_ERROR(src.u32(C, "FMF num_components"));
  BTFC_RETURN_IF_ERROR(src.u8(ss, "FMF scalar_size"));
  BTFC_RETURN_IF_ERROR(check_scalar_size(src, "FMF", ss));
  BTFC_RETURN_IF_ERROR(src.u32(C2, "FMF num_components (repeated)"));
  BTFC_RETURN_IF_ERROR(src.u32(nr, "FMF num_rows"));
  BTFC_RETURN_IF_ERROR(src.u32(nc, "FMF num_cols"));
  if (C != C2) return src.corrupt("FMF num_components " + std::to_string(C) + " and its repetition " + std::to_string(C2) + " differ");
  const BtfDesc& d = info.desc;
  if (uint64_t(nr) == uint64_t(d.channels) * d.num_texels() && uint64_t(nc) == d.num_images() && nr != d.abrdf_size())
    return unsupported(src.path() + ": FMF with images stacked column-wise (num_rows = channels x texels) is not supported");
  BTFC_RETURN_IF_ERROR(read_factors(src, "FMF", ss, C, nr, nc, d.abrdf_size(), "channels x num_lights x num_views", d.num_texels(), "rgb", blocks));
  info.scalar_sizes.push_back(ss);
  info.components.push_back(int(C));
  body.half = ss == 2;
  return {};
}

namespace {

struct Block {
  std::vector<float> U, SxV, S;
  size_t rows = 0;
  int C = 0;
};

Status write_common(ByteSink& out, const char* sig, const BtfDesc& d, const BonnMeta* meta, bool rotations) {
  BTFC_RETURN_IF_ERROR(out.open());
  out.bytes(sig, std::strlen(sig));
  write_meta(out, meta ? *meta : BonnMeta{}, d.channels);
  write_sampling(out, d);
  out.u32(uint32_t(d.width));
  out.u32(uint32_t(d.height));
  if (rotations) out.u32(0);
  return {};
}

// S is informational (no decoder uses it): clamped to the half range rather than failing.
std::vector<float> clamp_s(const float* s, int C, bool half) {
  std::vector<float> v(s, s + C);
  if (half)
    for (float& x : v) x = std::clamp(x, -65504.0f, 65504.0f);
  return v;
}

Status write_factors(ByteSink& out, const std::string& f, const float* S, const float* U, size_t rows, const float* SxV,
                     size_t texels, int C, bool half) {
  BTFC_RETURN_IF_ERROR(out.scalars(clamp_s(S, C, half).data(), size_t(C), half, f + " S"));
  BTFC_RETURN_IF_ERROR(out.scalars(U, rows * size_t(C), half, f + " U"));
  return out.scalars(SxV, texels * size_t(C), half, f + " SxV");
}

}  // namespace
}  // namespace bonn

Status write_bonn_dfmf(const Model& model, const std::string& path, bool half, const BonnMeta* meta) {
  using namespace bonn;
  BTFC_ASSIGN_OR_RETURN(FmfFactorsView fv, fmf_factors(model));
  const BtfDesc& d = model.desc();
  if (d.channels != 3) return unsupported(path + ": DFMF writing needs 3 channels, the model has " + std::to_string(d.channels));
  const size_t rows = d.num_images(), texels = d.num_texels();
  // A color=rgb model becomes colour model 0 exactly: channel c keeps the U rows of colour c and
  // shares SxV (stored once per channel, as the format requires).
  std::vector<Block> split;
  if (!fv.per_channel) {
    if (fv.bonn_color_model != 0)
      return unsupported(path + ": an FMF model with dynamic range reduction cannot be written as DFMF (write FMF)");
    const FmfBlockView& b = fv.blocks[0];
    for (int c = 0; c < 3; ++c) {
      Block s;
      s.C = b.C;
      s.rows = rows;
      s.U.resize(rows * size_t(b.C));
      for (size_t r = 0; r < rows; ++r) std::memcpy(&s.U[r * size_t(b.C)], b.U + (size_t(c) + 3 * r) * size_t(b.C), size_t(b.C) * 4);
      split.push_back(std::move(s));
    }
  }
  const int cm = fv.per_channel ? fv.bonn_color_model : 0;
  // Bonn's readers decode colour model 11 with the offset 1e-5, which the file cannot carry.
  if (fv.per_channel && cm == 11 && fv.drr_eps != 1e-5f)
    return unsupported(path + ": the dfmf model's luminance offset is " + real_string(fv.drr_eps) +
                       ", Bonn's colour model 11 fixes it at 1e-5 (readers would decode other values): encode with "
                       "fmf:color=dfmf:offset=1e-5 for a Bonn DFMF, or keep the model as .btfc");
  int cmax = 0;
  for (const FmfBlockView& b : fv.blocks) cmax = std::max(cmax, b.C);
  ByteSink out(path);
  BTFC_RETURN_IF_ERROR(write_common(out, "!DFMF08FCR", d, meta, true));
  out.u32(uint32_t(cmax));
  out.i32(cm);
  out.bytes(fv.color_mean, 12);
  out.bytes(fv.color_transform, 36);
  for (int c = 0; c < 3; ++c) {
    const FmfBlockView& b = fv.blocks[fv.per_channel ? size_t(c) : 0];
    const float* U = fv.per_channel ? b.U : split[size_t(c)].U.data();
    out.u8(half ? 2 : 4);
    out.u32(uint32_t(b.C));
    out.u32(uint32_t(rows));
    out.u32(uint32_t(texels));
    BTFC_RETURN_IF_ERROR(write_factors(out, "DFMF channel " + std::to_string(c), b.S, U, rows, b.SxV, texels, b.C, half));
  }
  return out.commit();
}

Status write_bonn_fmf(const Model& model, const std::string& path, bool half, const BonnMeta* meta) {
  using namespace bonn;
  BTFC_ASSIGN_OR_RETURN(FmfFactorsView fv, fmf_factors(model));
  const BtfDesc& d = model.desc();
  const size_t rows = d.abrdf_size(), texels = d.num_texels(), nc = size_t(d.channels);
  uint32_t drr = 0;
  // One rgb block as is; per-channel blocks of a linear-per-channel colour model (0, or 12 =
  // elementwise exp) merge exactly: C = sum of C_c, channel c's rows use only its column range.
  Block m;
  const FmfBlockView* one = nullptr;
  if (!fv.per_channel) {
    one = &fv.blocks[0];
    drr = fv.bonn_color_model == 12;
  } else {
    if (fv.bonn_color_model != 0 && fv.bonn_color_model != 12)
      return unsupported(path + ": a DFMF with colour model " + std::to_string(fv.bonn_color_model) +
                         " cannot be written as FMF exactly (only colour models 0 and 12 can)");
    drr = fv.bonn_color_model == 12;
    for (const FmfBlockView& b : fv.blocks) m.C += b.C;
    m.U.assign(rows * size_t(m.C), 0.0f);
    m.SxV.assign(texels * size_t(m.C), 0.0f);
    int off = 0;
    for (size_t c = 0; c < nc; ++c) {
      const FmfBlockView& b = fv.blocks[c];
      for (size_t r = 0; r < b.rows; ++r)
        std::memcpy(&m.U[(c + nc * r) * size_t(m.C) + size_t(off)], b.U + r * size_t(b.C), size_t(b.C) * 4);
      for (size_t t = 0; t < texels; ++t) std::memcpy(&m.SxV[t * size_t(m.C) + size_t(off)], b.SxV + t * size_t(b.C), size_t(b.C) * 4);
      m.S.insert(m.S.end(), b.S, b.S + b.C);
      off += b.C;
    }
  }
  const int C = one ? one->C : m.C;
  ByteSink out(path);
  BTFC_RETURN_IF_ERROR(write_common(out, "!FMF12FCER", d, meta, true));
  out.u8(2);  // header_version 2: dynamic range reduction flag + (empty) height map
  out.u32(drr);
  out.u32(0);
  out.u32(0);
  out.u32(uint32_t(C));
  out.u8(half ? 2 : 4);
  out.u32(uint32_t(C));
  out.u32(uint32_t(rows));
  out.u32(uint32_t(texels));
  BTFC_RETURN_IF_ERROR(one ? write_factors(out, "FMF", one->S, one->U, rows, one->SxV, texels, C, half)
                           : write_factors(out, "FMF", m.S.data(), m.U.data(), rows, m.SxV.data(), texels, C, half));
  return out.commit();
}

}  // namespace btfc
