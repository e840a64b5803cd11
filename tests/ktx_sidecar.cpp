// btfc_ktx_sidecar MODEL OUT.json [--float] [--direction-map N]
//
// Rebuilds the export bundle of MODEL in memory (the options `btfc export` was given) and writes
// what each texture must contain, for tests/ktx_parse_check.mjs to compare against its own,
// independent reading of the .ktx2 files (npm's ktx-parse + decoding by hand):
//   per texture: format, vk_format, type_size, width, height, layers, levels, channels,
//   per-level byte lengths and FNV-1a 64-bit hashes of the level bytes (hex), and the values of
//   the first texel of level 0 and of the last texel of the last level, as the bundle stores them.
// So the files are checked against the exporter's data, not against btfc's own KTX2 reader.
#include <cstdio>
#include <cstring>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "codecs/codec.h"
#include "core/container.h"
#include "formats/gpu/export.h"

using namespace btfc;

namespace {

std::string fnv1a64(const std::vector<uint8_t>& b) {
  uint64_t h = 0xcbf29ce484222325ull;
  for (uint8_t c : b) h = (h ^ c) * 0x100000001b3ull;
  char s[20];
  std::snprintf(s, sizeof s, "%016llx", static_cast<unsigned long long>(h));
  return s;
}

nlohmann::json texel(const gpu::GpuTexture& t, uint32_t level, size_t index) {
  const int ch = gpu::format_info(t.format).channels;
  nlohmann::json a = nlohmann::json::array();
  for (int c = 0; c < ch; ++c) {
    const size_t i = index * size_t(ch) + size_t(c);
    if (t.is_integer()) a.push_back(t.u[level][i]);
    else a.push_back(double(t.f[level][i]));  // float -> double exactly; dumped round-trip exact
  }
  return a;
}

int fail(const std::string& m) {
  std::fprintf(stderr, "btfc_ktx_sidecar: %s\n", m.c_str());
  return 1;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 3) return fail("usage: btfc_ktx_sidecar MODEL OUT.json [--float] [--direction-map N]");
  gpu::ExportOptions opt;
  for (int i = 3; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--float")) opt.half = false;
    else if (!std::strcmp(argv[i], "--direction-map") && i + 1 < argc) opt.direction_map = std::atoi(argv[++i]);
    else return fail(std::string("unknown option ") + argv[i]);
  }
  auto reader = ContainerReader::open(argv[1]);
  if (!reader.ok()) return fail(reader.status().message());
  auto model = load_model(reader.value());
  if (!model.ok()) return fail(model.status().message());
  auto b = gpu::build_export(*model.value(), opt);
  if (!b.ok()) return fail(b.status().message());
  nlohmann::json out;
  out["codec"] = b->codec;
  out["spec"] = b->spec;
  nlohmann::json tex = nlohmann::json::array();
  for (const gpu::GpuTexture& t : b->textures) {
    const gpu::FormatInfo& fi = gpu::format_info(t.format);
    nlohmann::json j = {{"name", t.name},       {"format", fi.name},       {"vk_format", fi.vk_format},   {"type_size", fi.bytes_per_channel},
                        {"channels", fi.channels}, {"width", t.width},      {"height", t.height},           {"layers", t.layers},
                        {"levels", t.num_levels()}, {"is_float", fi.is_float}, {"is_integer", fi.is_integer}, {"is_normalized", fi.is_normalized}};
    nlohmann::json lens = nlohmann::json::array(), hashes = nlohmann::json::array();
    for (uint32_t m = 0; m < t.num_levels(); ++m) {
      const std::vector<uint8_t> bytes = t.level_bytes(m);
      lens.push_back(bytes.size());
      hashes.push_back(fnv1a64(bytes));
    }
    j["level_bytes"] = lens;
    j["level_fnv1a64"] = hashes;
    const uint32_t last = t.num_levels() - 1;
    j["first_texel"] = texel(t, 0, 0);
    j["last_texel_last_level"] = texel(t, last, size_t(t.level_width(last)) * t.level_height(last) * t.num_layers() - 1);
    tex.push_back(j);
  }
  out["textures"] = tex;
  const std::string path = argv[2], tmp = path + ".tmp";
  {
    std::ofstream f(tmp);
    f << out.dump(2) << "\n";
    if (!f.good()) return fail(path + ": write failed");
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) return fail(path + ": cannot rename into place");
  return 0;
}
