// Writes an export bundle as a directory (formats/gpu/export.h): KTX2 textures, manifest.json,
// btf.frag and previews. Lives in btfc_io because previews go through OpenImageIO.
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>

#include "formats/gpu/export.h"
#include "formats/gpu/ktx2.h"
#include "formats/preview.h"

namespace btfc::gpu {
namespace {

namespace fs = std::filesystem;

Status write_text(const fs::path& p, const std::string& text) {
  std::ofstream f(p, std::ios::binary | std::ios::trunc);
  if (!f) return io_error(p.string() + ": cannot open for writing");
  f << text;
  if (!f.good()) return io_error(p.string() + ": write failed");
  return {};
}

// Layer 0, level 0 as an RGB image: float data as linear EXR (scale applied), integer data as a
// PNG of value / max (a visual check of index maps).
Status write_preview(const GpuTexture& t, const fs::path& dir) {
  const int ch = format_info(t.format).channels;
  RgbImage img;
  img.width = int(t.width), img.height = int(t.height);
  img.rgb.assign(size_t(img.width) * size_t(img.height) * 3, 0.f);
  double mx = 1;
  if (t.is_integer())
    for (size_t i = 0; i < size_t(t.width) * t.height * size_t(ch); ++i) mx = std::max(mx, double(t.u[0][i]));
  for (size_t p = 0; p < size_t(t.width) * t.height; ++p)
    for (int c = 0; c < 3; ++c) {
      const int sc = std::min(c, ch - 1);
      const size_t i = p * size_t(ch) + size_t(sc);
      img.rgb[p * 3 + size_t(c)] = t.is_integer() ? float(t.u[0][i] / mx) : float(t.f[0][i] * t.scale + t.bias);
    }
  return write_rgb_image((dir / (t.name + (t.is_integer() ? ".png" : ".exr"))).string(), img);
}

}  // namespace

Status write_export_dir(const ExportBundle& b, const std::string& dir, bool previews) {
  // "gpu/" names the directory gpu: without the slash the temporary is a sibling, not a child.
  std::string name = dir;
  while (name.size() > 1 && name.back() == '/') name.pop_back();
  const fs::path final_dir(name);
  std::error_code ec;
  if (fs::exists(final_dir, ec) && !fs::is_directory(final_dir, ec))
    return io_error(dir + ": exists and is not a directory");
  if (fs::is_directory(final_dir, ec) && !fs::is_empty(final_dir, ec))
    return io_error(dir + ": directory exists and is not empty (export writes a whole directory)");
  const fs::path tmp = final_dir.string() + ".tmp-export";
  fs::remove_all(tmp, ec);
  if (!fs::create_directories(tmp, ec)) return io_error(tmp.string() + ": cannot create: " + ec.message());
  auto fail = [&](Status s) {
    std::error_code e2;
    fs::remove_all(tmp, e2);
    return s;
  };
  for (const GpuTexture& t : b.textures) {
    const KeyValues kv = {{"btfc.codec", b.codec}, {"btfc.spec", b.spec}, {"btfc.texture", t.name}};
    if (Status s = write_ktx2(t, (tmp / (t.name + ".ktx2")).string(), kv); !s.ok()) return fail(s);
  }
  nlohmann::json manifest = manifest_json(b);
  if (b.write_extra) {
    Result<nlohmann::json> extra = b.write_extra(tmp.string());
    if (!extra.ok()) return fail(extra.status());
    manifest["files"] = extra.value();
  }
  if (Status s = write_text(tmp / "manifest.json", manifest.dump(2) + "\n"); !s.ok()) return fail(s);
  if (Status s = write_text(tmp / "btf.frag", b.glsl); !s.ok()) return fail(s);
  if (previews) {
    fs::create_directories(tmp / "previews", ec);
    for (const GpuTexture& t : b.textures)
      if (Status s = write_preview(t, tmp / "previews"); !s.ok()) return fail(s);
  }
  if (fs::is_directory(final_dir, ec)) fs::remove(final_dir, ec);  // empty (checked above)
  fs::rename(tmp, final_dir, ec);
  if (ec) return fail(io_error(dir + ": cannot move the export into place: " + ec.message()));
  return {};
}

}  // namespace btfc::gpu
