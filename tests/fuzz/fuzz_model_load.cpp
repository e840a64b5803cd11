// libFuzzer target: every registered codec's model loader (Codec::load) and the loaded model.
//
// Input: one selector byte, then a .btfc image. Selector 0 keeps the file's codec; any other
// value s rewrites the CODC chunk's codec name to all_codecs()[(s - 1) % n], so every codec in
// the registry (codecs/registry.cpp) is fed every input without a per-codec target: a codec
// added to the table is fuzzed from its first build. All CRCs are then repaired, so mutations
// reach the loaders' own checks (shapes, counts, scales, indices, spec strings) rather than
// stopping at the container's CRC check, which fuzz_container covers.
#include <algorithm>
#include <cstring>
#include <vector>

#include "core/container.h"
#include "tests/fuzz/fuzz_util.h"

using namespace btfc;

namespace {

uint32_t rd32(const std::vector<uint8_t>& b, size_t o) {
  return uint32_t(b[o]) | uint32_t(b[o + 1]) << 8 | uint32_t(b[o + 2]) << 16 | uint32_t(b[o + 3]) << 24;
}

// Replaces the codec name string at the start of the CODC payload, fixing the chunk size.
void set_codec_name(std::vector<uint8_t>& b, const std::string& name) {
  size_t pos = 32;
  while (pos <= b.size() && b.size() - pos >= 32) {
    uint64_t size = 0;
    for (int i = 0; i < 8; ++i) size |= uint64_t(b[pos + 8 + size_t(i)]) << (8 * i);
    if (size > b.size() - pos - 32) return;
    if (std::memcmp(&b[pos], "CODC", 4) == 0) {
      if (size < 4) return;
      const uint32_t len = rd32(b, pos + 32);
      if (len > size - 4) return;
      const size_t body = pos + 32, old_pad = size_t((16 - size % 16) % 16);
      std::vector<uint8_t> payload;
      for (int i = 0; i < 4; ++i) payload.push_back(uint8_t(name.size() >> (8 * i)));
      payload.insert(payload.end(), name.begin(), name.end());
      payload.insert(payload.end(), b.begin() + long(body + 4 + len), b.begin() + long(body + size));
      const uint64_t nsize = payload.size();
      payload.resize(payload.size() + size_t((16 - nsize % 16) % 16), 0);
      // The last chunk's padding may be cut off by the end of the input.
      b.erase(b.begin() + long(body), b.begin() + long(std::min(b.size(), body + size_t(size) + old_pad)));
      b.insert(b.begin() + long(body), payload.begin(), payload.end());
      for (int i = 0; i < 8; ++i) b[pos + 8 + size_t(i)] = uint8_t(nsize >> (8 * i));
      return;
    }
    pos += 32 + size_t(size) + size_t((16 - size % 16) % 16);
    if (pos > b.size()) return;
  }
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  fuzz::init_process();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static fuzz::MemFile file;
  if (size < 1) return 0;
  std::vector<uint8_t> b(data + 1, data + size);
  if (data[0] != 0) {
    const auto codecs = all_codecs();
    set_codec_name(b, codecs[size_t(data[0] - 1) % codecs.size()]->name());
  }
  fuzz::repair_crcs(b.data(), b.size());
  auto rd = ContainerReader::open(file.write(b.data(), b.size()));
  if (!rd.ok()) return 0;
  auto m = load_model(rd.value());
  if (m.ok()) fuzz::exercise(*m.value());
  return 0;
}
