// libFuzzer target: the BSVTF streaming file reader (formats/bsvtf/bsvtf.h), what `btfc
// tilecache` and a streaming client open: BsvtfReader::open (header, directions, blocks,
// directory), every packet and tile read of the first virtual textures (zlib payloads, varint
// DCT coefficients, prediction from the parent tile), the decoded eigen-ABRDFs / eigen-textures
// of block 0, and the tile-cache simulator (TileCacheSim::make, then a 2-frame run on a 16 x 12
// screen).
//
// Every CRC (header, directory, each payload) is repaired before the file is opened, as
// fuzz_model_load does for .btfc, so mutations reach the checks behind the CRCs (sizes,
// geometry, order, zlib, coefficients) instead of stopping at the first checksum. A file
// of at most 64 KiB must open or fail cleanly, never crash, hang or allocate beyond what the
// file could hold (libFuzzer's -malloc_limit_mb).
// Seeds: BSVTF files written by `btfc bsvtf` from the golden fmf models and from fmf models of
// crops of the real slice and the textile (tests/fuzz/make_seeds.sh), tile 8 so they stay small.
#include <zlib.h>

#include <algorithm>
#include <vector>

#include "formats/bsvtf/bsvtf.h"
#include "formats/bsvtf/tile_cache.h"
#include "tests/fuzz/fuzz_util.h"

using namespace btfc;

namespace {

uint64_t rd(const std::vector<uint8_t>& b, size_t o, int n) {
  uint64_t v = 0;
  for (int i = 0; i < n; ++i) v |= uint64_t(b[o + size_t(i)]) << (8 * i);
  return v;
}
void wr32(std::vector<uint8_t>& b, size_t o, uint32_t v) {
  for (int i = 0; i < 4; ++i) b[o + size_t(i)] = uint8_t(v >> (8 * i));
}

// Layout in bsvtf.h: header (header_bytes, its CRC in the last 4 bytes, the directory's CRC in
// the 4 before), directory of num_entries x 40 bytes (payload CRC at +36 of stored bytes at
// offset +16, length +24). Payload CRCs first, then the directory's, then the header's.
void repair_crcs(std::vector<uint8_t>& b) {
  if (b.size() < 80) return;
  const uint64_t hb = rd(b, 12, 4), n = rd(b, 64, 8);
  if (hb < 88 || hb > b.size()) return;
  if (n <= (b.size() - hb) / 40) {
    for (uint64_t e = 0; e < n; ++e) {
      const size_t o = size_t(hb + 40 * e);
      const uint64_t off = rd(b, o + 16, 8), len = rd(b, o + 24, 4);
      if (off <= b.size() && len <= b.size() - off) wr32(b, o + 36, uint32_t(crc32(0, b.data() + off, uInt(len))));
    }
    wr32(b, size_t(hb) - 8, uint32_t(crc32(0, b.data() + hb, uInt(40 * n))));
  }
  wr32(b, size_t(hb) - 4, uint32_t(crc32(0, b.data(), uInt(hb - 4))));
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  fuzz::init_process();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static fuzz::MemFile file;
  std::vector<uint8_t> b(data, data + size);
  repair_crcs(b);
  const std::string& path = file.write(b.data(), b.size());
  auto r = BsvtfReader::open(path);
  if (!r.ok()) {
    if (r.status().message().find(path) == std::string::npos) __builtin_trap();
    return 0;
  }
  const BsvtfReader& f = r.value();
  for (size_t t = 0; t < std::min<size_t>(f.textures(), 2); ++t) {
    (void)f.read_packet(t);
    (void)f.decode_texture(t);
  }
  (void)f.decode_eigen_abrdfs(0);
  (void)f.decode_eigen_textures(0);
  auto sim = TileCacheSim::make(f);
  if (sim.ok()) {
    TileCacheOptions o;
    o.cache_tiles = 8;
    o.path.frames = 2, o.path.width = 16, o.path.height = 12;
    (void)sim->run(o);
  }
  return 0;
}
