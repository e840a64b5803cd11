// Decompression bombs (issue 25): a small file that declares a huge decode is refused before
// anything of that size is allocated, with an error that says so, for every codec.
//
// A model's file grows with texels + directions while its decode grows with texels x directions,
// so every codec's files "declare" decodes hundreds of times their size, and a hostile header can
// declare more. Two ways in, both per golden model (tests/golden/, one per registered codec):
//  - the real model under a memory limit below its decode (the limit stands for "more than this
//    machine has"): decode_all fails with the memory-limit error and its output stays empty;
//  - the same file with its DESC rewritten to declare 2^15 x 2^15 texels (CRCs repaired, so the
//    loaders' own checks are what stops it): loading fails with a clear error naming the file, or
//    a loaded model refuses the decode; the peak RSS does not grow by anything near the declared size.
// And the default limit (no BTFC_MAX_MEMORY) is the machine's memory, so a declared decode
// larger than the RAM is refused without the user setting anything.
#include <gtest/gtest.h>
#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "codecs/codec.h"
#include "core/container.h"
#include "core/limits.h"
#include "core/sysinfo.h"
#include "tests/test_paths.h"

using namespace btfc;

namespace {

const std::string k_dir = std::string(BTFC_SOURCE_DIR) + "/tests/golden/";

struct LimitGuard {
  ~LimitGuard() { set_memory_limit(0); }
};

std::vector<uint8_t> slurp(const std::string& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), {}};
}

void spit(const std::string& p, const std::vector<uint8_t>& b) {
  std::ofstream(p, std::ios::binary).write(reinterpret_cast<const char*>(b.data()), std::streamsize(b.size()));
}

uint64_t rd64(const std::vector<uint8_t>& b, size_t o) {
  uint64_t v = 0;
  for (int i = 0; i < 8; ++i) v |= uint64_t(b[o + size_t(i)]) << (8 * i);
  return v;
}
void wr32(std::vector<uint8_t>& b, size_t o, uint32_t v) {
  for (int i = 0; i < 4; ++i) b[o + size_t(i)] = uint8_t(v >> (8 * i));
}

// Sets DESC's width and height and repairs that chunk's CRC (docs/FORMAT.md: 32-byte file
// header, chunks of a 32-byte header + payload padded to 16; the CRC covers the header's first
// 28 bytes and the payload). Returns false when the file has no DESC.
bool declare_texels(std::vector<uint8_t>& b, uint32_t w, uint32_t h) {
  for (size_t pos = 32; pos + 32 <= b.size();) {
    const uint64_t size = rd64(b, pos + 8);
    if (std::memcmp(&b[pos], "DESC", 4) == 0) {
      wr32(b, pos + 32, w);
      wr32(b, pos + 36, h);
      uint32_t c = uint32_t(crc32(0, &b[pos], 28));
      c = uint32_t(crc32(c, &b[pos + 32], uInt(size)));
      wr32(b, pos + 28, c);
      return true;
    }
    pos += 32 + size_t(size) + size_t((16 - size % 16) % 16);
  }
  return false;
}

std::vector<std::string> golden_models() {
  std::vector<std::string> names;
  for (const auto& e : std::filesystem::directory_iterator(k_dir)) {
    const std::string f = e.path().filename().string();
    if (f.ends_with(".btfc") && !f.ends_with(".decoded.btfc") && f != "input.btfc") names.push_back(f);
  }
  std::sort(names.begin(), names.end());
  return names;
}

bool mentions_limit(const Status& s) { return s.message().find("memory limit") != std::string::npos; }

}  // namespace

TEST(Bomb, EveryCodecHasAGoldenModelToBombWith) {
  // The loop below covers what tests/golden holds; a registered codec without a golden file
  // would be left out silently.
  const auto files = golden_models();
  for (const Codec* c : all_codecs()) {
    if (std::string(c->name()) == "toy") continue;  // the test-only codec (tests/toy_codec) has no golden file
    EXPECT_NE(std::find(files.begin(), files.end(), std::string(c->name()) + ".btfc"), files.end()) << c->name();
  }
}

TEST(Bomb, EveryCodecRefusesADecodeOverTheLimitBeforeAllocating) {
  LimitGuard g;
  for (const std::string& f : golden_models()) {
    SCOPED_TRACE(f);
    auto rd = ContainerReader::open(k_dir + f);
    ASSERT_TRUE(rd.ok()) << rd.status().message();
    auto m = load_model(rd.value());
    ASSERT_TRUE(m.ok()) << m.status().message();
    const uint64_t decoded = m.value()->desc().num_values() * sizeof(float);
    set_memory_limit(size_t(decoded / 2));
    Btf out;
    const Status s = m.value()->decode_all(out);
    EXPECT_FALSE(s.ok());
    EXPECT_TRUE(mentions_limit(s)) << s.message();
    EXPECT_EQ(out.size(), 0u);  // (the golden decodes are tens of KB: too small to see in the RSS; the next test is not)
    set_memory_limit(0);
    EXPECT_TRUE(m.value()->decode_all(out).ok());  // and it was the limit, not the model
  }
}

TEST(Bomb, ARawBtfOverTheLimitIsRefusedNamingTheFile) {
  // The uncompressed input a user compresses (btfc compress in.btfc): the memory-limit error
  // names the file, as every other error of a reader does.
  LimitGuard g;
  auto rd = ContainerReader::open(k_dir + "input.btfc");
  ASSERT_TRUE(rd.ok()) << rd.status().message();
  set_memory_limit(size_t(rd.value().desc().num_values() * sizeof(float) / 2));
  auto b = load_raw_btf(rd.value());
  ASSERT_FALSE(b.ok());
  EXPECT_TRUE(mentions_limit(b.status())) << b.status().message();
  EXPECT_NE(b.status().message().find(k_dir + "input.btfc"), std::string::npos) << b.status().message();
  set_memory_limit(0);
  EXPECT_TRUE(load_raw_btf(rd.value()).ok());
}

TEST(Bomb, EveryCodecRefusesAFileDeclaringAHugeBtf) {
  LimitGuard g;
  set_memory_limit(size_t(256) << 20);  // stands for this machine's RAM: the declared BTF is 2^15 x 2^15 texels
  const std::string tmp = ::testing::TempDir() + "bomb_" + std::to_string(getpid()) + ".btfc";
  for (const std::string& f : golden_models()) {
    SCOPED_TRACE(f);
    std::vector<uint8_t> b = slurp(k_dir + f);
    ASSERT_TRUE(declare_texels(b, 1u << 15, 1u << 15));
    spit(tmp, b);
    const uint64_t rss0 = peak_rss_bytes();
    auto rd = ContainerReader::open(tmp);
    ASSERT_TRUE(rd.ok()) << rd.status().message();  // the container itself is intact
    auto m = load_model(rd.value());
    if (!m.ok()) {
      // Refused while loading: the tensors disagree with the declared texels, or the model's
      // expanded tensors would not fit. Either way the message names the file.
      EXPECT_NE(m.status().message().find(tmp), std::string::npos) << m.status().message();
    } else {
      Btf out;
      const Status s = m.value()->decode_all(out);
      EXPECT_FALSE(s.ok());
      EXPECT_TRUE(mentions_limit(s)) << s.message();
      EXPECT_EQ(out.size(), 0u);
    }
    EXPECT_LT(peak_rss_bytes() - rss0, uint64_t(64) << 20) << "peak RSS grew by " << (peak_rss_bytes() - rss0) << " bytes";
  }
  std::remove(tmp.c_str());
}

TEST(Bomb, TheDefaultLimitIsTheMachinesMemory) {
  LimitGuard g;
  const long pages = sysconf(_SC_PHYS_PAGES), page = sysconf(_SC_PAGE_SIZE);
  ASSERT_GT(pages, 0);
  const uint64_t ram = uint64_t(pages) * uint64_t(page);
  EXPECT_GT(default_memory_limit(), 0u);
  EXPECT_LE(default_memory_limit(), std::min<uint64_t>(ram, k_max_default_memory_limit));
  if (std::getenv("BTFC_MAX_MEMORY") == nullptr) {
    set_memory_limit(0);
    EXPECT_EQ(memory_limit(), default_memory_limit());
    // A declared BTF bigger than the machine: refused by default, before allocating.
    BtfDesc d;
    d.lights = DirectionSet::ubo2003();
    d.views = DirectionSet::ubo2003();
    d.channels = 3;
    const uint64_t per_texel = 81ull * 81 * 3 * sizeof(float);
    int side = 1;
    while (uint64_t(side) * uint64_t(side) * per_texel <= default_memory_limit() && side < (1 << 20)) side *= 2;
    d.width = d.height = side;
    auto r = Btf::create(d);
    ASSERT_FALSE(r.ok());
    EXPECT_TRUE(mentions_limit(r.status())) << r.status().message();
  }
}
