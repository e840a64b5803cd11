// libFuzzer target: scene files (core/scene.h), the JSON a user passes to `btfc export --scene`.
//
// Input: the file's text, optionally followed by a NUL byte and a material name (--material;
// none = the first material). The text goes through read_scene (written to a memfd, so the
// file path is the one a user's file takes) and parse_scene; an accepted scene is then used the
// way the exporter uses it: scene_mip_range and directions_in_cone on the UBO2003 sampling.
// Any JSON, any key of any type, must give a clean error naming the file, never an exception
// escaping the parser (nlohmann::json throws on a wrong type) or a crash.
#include <cmath>
#include <cstring>
#include <string>

#include "core/scene.h"
#include "tests/fuzz/fuzz_util.h"

using namespace btfc;

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  fuzz::init_process();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static fuzz::MemFile file;
  static const DirectionSet ubo = DirectionSet::ubo2003();
  const uint8_t* nul = static_cast<const uint8_t*>(std::memchr(data, 0, size));
  const size_t text_len = nul ? size_t(nul - data) : size;
  const std::string material = nul ? std::string(reinterpret_cast<const char*>(nul + 1), size - text_len - 1) : std::string();
  const std::string& path = file.write(data, text_len);
  auto s = gpu::read_scene(path, material);
  auto t = gpu::parse_scene(std::string(reinterpret_cast<const char*>(data), text_len), path, material);
  if (s.ok() != t.ok()) __builtin_trap();  // the two entry points must agree
  if (!s.ok()) {
    // Errors name the file (the memfd path) so a user knows which --scene was wrong.
    if (s.status().message().find(path) == std::string::npos) __builtin_trap();
    return 0;
  }
  const gpu::SceneMaterial& m = s.value();
  if (!(m.footprint_min > 0 && m.footprint_min <= m.footprint_max)) __builtin_trap();
  int first = 0, last = 0;
  gpu::scene_mip_range(m, first, last);
  if (first < 0 || last < first) __builtin_trap();
  for (const auto& cone : {m.light_cone, m.view_cone}) {
    const std::vector<int> dirs = gpu::directions_in_cone(ubo, cone);
    if (dirs.empty() || dirs.size() > ubo.size()) __builtin_trap();
  }
  return 0;
}
