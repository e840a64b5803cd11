#include "codecs/gpu_export.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "core/interp.h"

namespace btfc::gpu {

// The exporters are the registry's (codecs/registry.cpp: one entry names codec and exporter).
const Exporter* find_exporter(const std::string& codec) {
  for (const CodecEntry& e : codec_registry())
    if (codec == e.codec->name()) return e.exporter;
  return nullptr;
}

const GpuTexture* ExportBundle::find(const std::string& name) const {
  for (const GpuTexture& t : textures)
    if (t.name == name) return &t;
  return nullptr;
}

uint64_t ExportBundle::clamped() const {
  uint64_t n = 0;
  for (const GpuTexture& t : textures) n += t.clamped;
  return n;
}

uint64_t ExportBundle::texture_bytes() const {
  uint64_t n = 0;
  for (const GpuTexture& t : textures) n += t.total_bytes();
  return n;
}

Result<ExportBundle> build_export(const Model& model, const ExportOptions& opt) {
  const std::string codec = model.spec().substr(0, model.spec().find(':'));
  const Exporter* e = find_exporter(codec);
  if (!e) return unsupported("export: codec '" + codec + "' has no GPU exporter");
  if (opt.direction_map < 2 || opt.direction_map > 1024)
    return invalid_argument("export: direction map size " + std::to_string(opt.direction_map) + " outside 2..1024");
  BTFC_ASSIGN_OR_RETURN(ExportBundle b, e->build(model, opt));
  b.codec = codec, b.spec = model.spec(), b.desc = model.desc(), b.model_payload_bytes = model.payload_bytes();
  if (opt.scene) {
    const uint64_t bytes = b.texture_bytes(), budget = opt.scene->gpu_budget;
    if (b.scene_report.is_null())  // the codec keeps everything: only the budget applies
      b.scene_report = {{"kept", "everything (this codec's exporter does not cut by scene)"}, {"predicted_added_rel_error", 0.0}};
    b.scene_report["material"] = opt.scene->name;
    b.scene_report["bytes"] = bytes;
    b.scene_report["gpu_budget"] = budget;
    if (budget && bytes > budget)
      return invalid_argument("export: the textures need " + std::to_string(bytes) + " bytes, over the scene's GPU budget of " +
                              std::to_string(budget) + " bytes");
  }
  // OpenGL ES 3.0 guarantees only 2048 texels per side and 256 array layers (desktop GPUs and
  // llvmpipe allow 16384 / 2048): larger textures load on most, but not every, GLES device.
  for (const GpuTexture& t : b.textures)
    if (t.width > 2048 || t.height > 2048 || t.layers > 256)
      b.warnings.push_back("texture '" + t.name + "' (" + std::to_string(t.width) + " x " + std::to_string(t.height) + " x " +
                           std::to_string(t.num_layers()) + ") exceeds the OpenGL ES 3.0 minimum limits (2048 per side, 256 layers)");
  if (const uint64_t c = b.clamped())
    b.warnings.push_back(std::to_string(c) + " values clamped to the range of their texture format (half: +-65504)");
  return b;
}

nlohmann::json direction_table(const DirectionSet& set) {
  nlohmann::json a = nlohmann::json::array();
  for (const Vec3& d : set.dirs) a.push_back({d.x, d.y, d.z});
  return a;
}

void uv_texel(float u, float v, int width, int height, int& x, int& y) {
  x = std::clamp(int(std::floor(u * float(width))), 0, width - 1);
  y = std::clamp(int(std::floor(v * float(height))), 0, height - 1);
}

void direction_cell(const Vec3& d, int n, int& cx, int& cy) {
  const float s = 1.0f / (1.0f + std::max(d.z, 0.0f));
  const float px = d.x * s, py = d.y * s;
  cx = std::clamp(int(std::floor((px * 0.5f + 0.5f) * float(n))), 0, n - 1);
  cy = std::clamp(int(std::floor((py * 0.5f + 0.5f) * float(n))), 0, n - 1);
}

const char* glsl_common() {
  return R"(// ---- btfc common ----
ivec2 btfc_texel(vec2 uv, ivec2 size) {
  return clamp(ivec2(floor(uv * vec2(size))), ivec2(0), size - 1);
}
// Cell of an n x n parabolic direction map: p = (x, y) / (1 + z), [-1, 1]^2 -> [0, n)^2.
ivec2 btfc_dir_cell(vec3 d, int n) {
  vec2 p = d.xy * (1.0 / (1.0 + max(d.z, 0.0)));
  return clamp(ivec2(floor((p * 0.5 + 0.5) * float(n))), ivec2(0), ivec2(n - 1));
}
)";
}

std::string glsl_float(double v) {
  char s[64];
  std::snprintf(s, sizeof s, "%.9g", v);
  std::string r = s;
  if (r.find_first_of(".en") == std::string::npos) r += ".0";  // "inf"/"nan" never occur: data are checked finite
  return r;
}

std::string glsl_delaunay_function(const std::string& signature, const std::string& prologue, const std::string& measured_call) {
  return signature + " {  // Delaunay interpolation, 9 lookups\n" + prologue +
         "  ivec2 cl = btfc_dir_cell(wl, DIR_N), cv = btfc_dir_cell(wv, DIR_N);\n"
         "  uvec4 il = texelFetch(u_dir_index, ivec3(cl, 0), 0), iv = texelFetch(u_dir_index, ivec3(cv, 1), 0);\n"
         "  vec4 al = texelFetch(u_dir_weight, ivec3(cl, 0), 0), av = texelFetch(u_dir_weight, ivec3(cv, 1), 0);\n"
         "  vec3 acc = vec3(0.0);\n"
         "  for (int i = 0; i < 3; ++i)\n"
         "    for (int j = 0; j < 3; ++j) {\n"
         "      float w = al[i] * av[j];\n"
         "      if (w != 0.0) acc += w * " + measured_call + ";\n"
         "    }\n"
         "  return acc;\n}\n";
}

void emulate_delaunay(const ExportBundle& b, const Vec3& wl, const Vec3& wv, const std::function<void(int l, int v, float* rgb)>& measured,
                      float* rgb) {
  const GpuTexture &I = *b.find("dir_index"), &W = *b.find("dir_weight");
  const int n = int(I.width);
  int lx, ly, vx, vy;
  direction_cell(wl, n, lx, ly);
  direction_cell(wv, n, vx, vy);
  const size_t la = (size_t(ly) * size_t(n) + size_t(lx)) * 4, va = ((size_t(n) + size_t(vy)) * size_t(n) + size_t(vx)) * 4;
  float acc[3] = {0, 0, 0}, tmp[3];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      const float w = W.f[0][la + size_t(i)] * W.f[0][va + size_t(j)];
      if (w == 0) continue;
      measured(int(I.u[0][la + size_t(i)]), int(I.u[0][va + size_t(j)]), tmp);
      for (int c = 0; c < 3; ++c) acc[c] += w * tmp[c];
    }
  std::copy(acc, acc + 3, rgb);
}

Result<std::pair<GpuTexture, GpuTexture>> direction_maps(const BtfDesc& desc, int n) {
  const size_t nn = size_t(n) * size_t(n);
  std::vector<uint32_t> idx(2 * nn * 4, 0);
  std::vector<float> w(2 * nn * 4, 0.f);
  for (int layer = 0; layer < 2; ++layer) {
    const DirectionSet& set = layer == 0 ? desc.lights : desc.views;
    if (set.size() > 65535) return unsupported("export: more than 65535 directions do not fit the 16-bit index map");
    const DirectionInterpolator interp(set);
    for (int cy = 0; cy < n; ++cy)
      for (int cx = 0; cx < n; ++cx) {
        // Texel centre in parabolic coordinates -> direction (outside the disc: the rim).
        double px = (cx + 0.5) / n * 2 - 1, py = (cy + 0.5) / n * 2 - 1, r2 = px * px + py * py;
        if (r2 > 1) {
          const double r = std::sqrt(r2);
          px /= r, py /= r, r2 = 1;
        }
        const double s = 1 / (1 + r2);
        const Vec3 d{float(2 * px * s), float(2 * py * s), float((1 - r2) * s)};
        const DirWeights dw = interp.weights(d);
        const size_t at = ((size_t(layer) * size_t(n) + size_t(cy)) * size_t(n) + size_t(cx)) * 4;
        for (int k = 0; k < 3; ++k) idx[at + size_t(k)] = uint32_t(dw.index[size_t(k)]), w[at + size_t(k)] = dw.weight[size_t(k)];
      }
  }
  BTFC_ASSIGN_OR_RETURN(GpuTexture ti, make_uint_texture("dir_index", TexFormat::rgba16_uint, uint32_t(n), uint32_t(n), 2, std::move(idx)));
  BTFC_ASSIGN_OR_RETURN(GpuTexture tw, make_float_texture("dir_weight", TexFormat::rgba32f, uint32_t(n), uint32_t(n), 2, std::move(w)));
  ti.meaning = "Delaunay triangle of each parabolic-map cell: 3 direction indices (layer 0 lights, 1 views)";
  ti.channel_meaning = {"index 0", "index 1", "index 2", "unused"};
  tw.meaning = "barycentric weights of those 3 directions at the cell centre (sum 1)";
  tw.channel_meaning = {"weight 0", "weight 1", "weight 2", "unused"};
  return std::make_pair(std::move(ti), std::move(tw));
}

}  // namespace btfc::gpu
