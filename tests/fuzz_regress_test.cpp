// Regression inputs of the fuzz targets added for issue 25 (tests/fuzz/fuzz_scene.cpp,
// fuzz_bsvtf.cpp, fuzz_mlvq_indices.cpp), kept in tests/corrupt/ next to the container and Bonn
// ones (tests/corrupt_test.cpp). Each must give a clean error, never a crash, sanitizer report or
// huge allocation. By extension:
//   *.scene     a scene file (core/scene.h read_scene; --scene of btfc export): error naming the file
//   *.bsvtf     a BSVTF streaming file as the fuzz target saw it (CRCs repaired): BsvtfReader::open,
//               then every packet and tile of the first textures and the tile-cache simulator
//   *.mlvqidx   an mlvq index stream in fuzz_mlvq_indices' decode layout (byte 0 even, u32 count,
//               u32 alphabet, the stream): decode_indices
// Image sets (*.imageset) are replayed by tests/io/fuzz_regress_io_test.cpp (OpenImageIO side).
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <iterator>

#include "codecs/mlvq/mlvq_internal.h"
#include "core/limits.h"
#include "core/scene.h"
#include "formats/bsvtf/bsvtf.h"
#include "formats/bsvtf/tile_cache.h"
#include "tests/test_paths.h"

using namespace btfc;
namespace fs = std::filesystem;

namespace {

const fs::path k_dir = fs::path(BTFC_SOURCE_DIR) / "tests" / "corrupt";

std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), {}};
}

Status open_bsvtf(const std::string& path) {
  BTFC_ASSIGN_OR_RETURN(BsvtfReader f, BsvtfReader::open(path));
  for (size_t t = 0; t < std::min<size_t>(f.textures(), 2); ++t) {
    BTFC_RETURN_IF_ERROR(f.read_packet(t).status());
    BTFC_RETURN_IF_ERROR(f.decode_texture(t).status());
  }
  BTFC_ASSIGN_OR_RETURN(TileCacheSim sim, TileCacheSim::make(f));
  TileCacheOptions o;
  o.cache_tiles = 8;
  o.path.frames = 2, o.path.width = 16, o.path.height = 12;
  return sim.run(o).status();
}

}  // namespace

TEST(FuzzRegress, EveryFileFailsCleanly) {
  // The fuzz targets' limit (tests/fuzz/fuzz_util.h): sizes that only the memory limit bounds (an
  // index stream of a 1-entry codebook stores no bits) must fail here, not allocate 16 GB.
  set_memory_limit(size_t(64) << 20);
  int checked = 0;
  for (const auto& e : fs::directory_iterator(k_dir)) {
    const std::string p = e.path().string(), ext = e.path().extension().string();
    Status s;
    if (ext == ".scene") {
      s = gpu::read_scene(p).status();
      if (!s.ok()) {
        EXPECT_NE(s.message().find(p), std::string::npos) << "error does not name the file: " << s.message();
      }
    } else if (ext == ".bsvtf") {
      s = open_bsvtf(p);
      if (!s.ok()) {
        EXPECT_NE(s.message().find(p), std::string::npos) << "error does not name the file: " << s.message();
      }
    } else if (ext == ".mlvqidx") {
      const std::string b = slurp(e.path());
      ASSERT_GE(b.size(), 9u) << p;
      auto u32 = [&](size_t o) {
        uint32_t v = 0;
        for (int i = 0; i < 4; ++i) v |= uint32_t(uint8_t(b[o + size_t(i)])) << (8 * i);
        return v;
      };
      const auto* bytes = reinterpret_cast<const uint8_t*>(b.data());
      s = mlvq::decode_indices(std::span<const uint8_t>(bytes + 9, b.size() - 9), u32(1), u32(5), p).status();
    } else {
      continue;
    }
    EXPECT_FALSE(s.ok()) << p << ": accepted, expected a clean error";
    if (!s.ok()) {
      EXPECT_NE(s.code(), StatusCode::codec_error) << p << ": " << s.message();
    }
    ++checked;
  }
  set_memory_limit(0);
  // Other tests own the other extensions; this one needs at least one file of its own.
  EXPECT_GE(checked, 1);
}
