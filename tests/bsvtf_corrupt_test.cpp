// Hostile .bsvtf files: every damage gives a clear error naming the file, never a crash.
#include <gtest/gtest.h>
#include <zlib.h>

#include <cstring>
#include <fstream>
#include <iterator>
#include <limits>

#include "formats/bsvtf/bsvtf.h"
#include "tests/bsvtf_fixture.h"

using namespace btfc;
using namespace bsvtf_test;

namespace {

using Bytes = std::vector<uint8_t>;

Bytes slurp(const std::string& p) {
  std::ifstream f(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(f), {}};
}
void spit(const std::string& p, const Bytes& b) {
  std::ofstream f(p, std::ios::binary | std::ios::trunc);
  f.write(reinterpret_cast<const char*>(b.data()), std::streamsize(b.size()));
}
uint32_t get32(const Bytes& b, size_t o) { return uint32_t(b[o]) | uint32_t(b[o + 1]) << 8 | uint32_t(b[o + 2]) << 16 | uint32_t(b[o + 3]) << 24; }
void put32(Bytes& b, size_t o, uint32_t v) {
  for (int i = 0; i < 4; ++i) b[o + size_t(i)] = uint8_t(v >> (8 * i));
}
// Recomputes both CRCs, so that a test reaches the size checks behind them.
void fix_crcs(Bytes& b) {
  const uint32_t hb = get32(b, 12);
  uint64_t n = 0;
  for (int i = 0; i < 8; ++i) n |= uint64_t(b[64 + size_t(i)]) << (8 * i);
  if (hb + 40 * n <= b.size()) put32(b, hb - 8, uint32_t(crc32(0, b.data() + hb, uInt(40 * n))));
  put32(b, hb - 4, uint32_t(crc32(0, b.data(), hb - 4)));
}

class BsvtfCorrupt : public ::testing::Test {
 protected:
  void SetUp() override {
    model = make_model(140, 70, 6, 0.1, 9);
    ASSERT_TRUE(model);
    good = tmp_path("good.bsvtf");
    BsvtfOptions o;
    o.tile = 32;
    ASSERT_TRUE(write_bsvtf(*model, o, good, nullptr).ok());
    bytes = slurp(good);
    bad = tmp_path("bad.bsvtf");
  }
  // Opens the damaged bytes; expects failure with `code`, the path and `needle` in the message.
  void expect_open_error(const Bytes& b, StatusCode code, const std::string& needle) {
    spit(bad, b);
    auto r = BsvtfReader::open(bad);
    ASSERT_FALSE(r.ok()) << needle;
    EXPECT_EQ(r.status().code(), code) << r.status().message();
    EXPECT_NE(r.status().message().find(bad), std::string::npos) << r.status().message();
    EXPECT_NE(r.status().message().find(needle), std::string::npos) << r.status().message();
  }
  std::unique_ptr<Model> model;
  std::string good, bad;
  Bytes bytes;
};

}  // namespace

TEST_F(BsvtfCorrupt, GoodFileOpens) {
  auto r = BsvtfReader::open(good);
  ASSERT_TRUE(r.ok()) << r.status().message();
  EXPECT_EQ(r->file_bytes(), bytes.size());
  EXPECT_EQ(r->geometry().levels, 4);  // 140 -> 70 -> 35 -> 18 in 32-texel tiles
}

TEST_F(BsvtfCorrupt, MissingFile) {
  auto r = BsvtfReader::open(bad + ".absent");
  EXPECT_EQ(r.status().code(), StatusCode::io_error);
  EXPECT_NE(r.status().message().find(".absent"), std::string::npos);
}

TEST_F(BsvtfCorrupt, WrongMagic) {
  Bytes b = bytes;
  b[0] = 'X';
  expect_open_error(b, StatusCode::corrupt_data, "wrong magic");
}

TEST_F(BsvtfCorrupt, NewerMajorVersion) {
  Bytes b = bytes;
  b[8] = 2;
  spit(bad, b);
  EXPECT_EQ(BsvtfReader::open(bad).status().code(), StatusCode::unsupported);
}

TEST_F(BsvtfCorrupt, TruncatedAnywhere) {
  // Cut inside the fixed header, the directions, the directory and the last payload.
  for (size_t len : {size_t(0), size_t(7), size_t(79), size_t(200), size_t(get32(bytes, 12) + 100), bytes.size() - 1}) {
    Bytes b(bytes.begin(), bytes.begin() + std::ptrdiff_t(len));
    spit(bad, b);
    auto r = BsvtfReader::open(bad);
    ASSERT_FALSE(r.ok()) << len;
    EXPECT_EQ(r.status().code(), StatusCode::corrupt_data) << len;
    EXPECT_NE(r.status().message().find("truncated"), std::string::npos) << len << ": " << r.status().message();
  }
}

TEST_F(BsvtfCorrupt, TrailingBytes) {
  Bytes b = bytes;
  b.push_back(0);
  expect_open_error(b, StatusCode::corrupt_data, "file is");
}

TEST_F(BsvtfCorrupt, FlippedBitsAreCaughtByTheChecksums) {
  Bytes b = bytes;
  b[100] ^= 1;  // a direction
  expect_open_error(b, StatusCode::corrupt_data, "header checksum");
  b = bytes;
  b[get32(bytes, 12) + 45] ^= 1;  // the second directory entry
  expect_open_error(b, StatusCode::corrupt_data, "directory checksum");
}

TEST_F(BsvtfCorrupt, SizesThatDisagree) {
  Bytes b = bytes;
  put32(b, 16, 400);  // width: a different pyramid
  fix_crcs(b);
  expect_open_error(b, StatusCode::corrupt_data, "levels");
  b = bytes;
  put32(b, 12, get32(b, 12) + 8);  // header_bytes
  fix_crcs(b);
  expect_open_error(b, StatusCode::corrupt_data, "header_bytes");
  b = bytes;
  put32(b, 24, 60);  // tile size: 68 not a multiple of 8
  fix_crcs(b);
  expect_open_error(b, StatusCode::corrupt_data, "multiple of 8");
  b = bytes;
  b[64] = uint8_t(b[64] + 1);  // num_entries
  fix_crcs(b);
  expect_open_error(b, StatusCode::corrupt_data, "");
  b = bytes;
  const uint32_t hb = get32(bytes, 12);
  put32(b, hb + 40 * 3 + 24, get32(b, hb + 40 * 3 + 24) + 1);  // a stored size
  fix_crcs(b);
  expect_open_error(b, StatusCode::corrupt_data, "entry 4");  // its successor no longer follows
  b = bytes;
  b[hb + 40 * 5] = 1;  // a tile entry claiming to be a packet
  fix_crcs(b);
  expect_open_error(b, StatusCode::corrupt_data, "out of order");
}

TEST_F(BsvtfCorrupt, DamagedPayloadFailsOnRead) {
  auto r = BsvtfReader::open(good).value();
  const size_t e = bsvtf_tile_entry(r.geometry(), r.textures(), 1, 2, 1, 0);
  Bytes b = bytes;
  b[r.entries()[e].offset + 3] ^= 0x40;
  spit(bad, b);
  auto d = BsvtfReader::open(bad);
  ASSERT_TRUE(d.ok()) << d.status().message();  // payloads are checked on demand
  auto levels = d->decode_texture(1);
  ASSERT_FALSE(levels.ok());
  EXPECT_NE(levels.status().message().find("checksum mismatch"), std::string::npos) << levels.status().message();
  EXPECT_NE(levels.status().message().find(bad), std::string::npos);
  EXPECT_TRUE(d->decode_texture(0).ok());  // other textures are unaffected
}

// Damage behind valid checksums (the entry's CRC, the directory CRC and the header CRC all
// recomputed): the inflate and varint checks must still refuse it, or decode something, but
// never read out of bounds (run under ASan by scripts/test-sanitize.sh).
TEST_F(BsvtfCorrupt, GarbageBehindValidChecksums) {
  auto r = BsvtfReader::open(good).value();
  const uint32_t hb = get32(bytes, 12);
  std::mt19937 rng(5);
  int refused = 0;
  for (int trial = 0; trial < 40; ++trial) {
    const size_t e = rng() % r.entries().size();
    const BsvtfEntry& x = r.entries()[e];
    Bytes b = bytes;
    for (int k = 0; k < 3; ++k) b[x.offset + rng() % x.stored] ^= uint8_t(1 + rng() % 255);
    put32(b, hb + 40 * e + 36, uint32_t(crc32(0, b.data() + x.offset, uInt(x.stored))));
    fix_crcs(b);
    spit(bad, b);
    auto d = BsvtfReader::open(bad);
    ASSERT_TRUE(d.ok()) << d.status().message();
    const size_t t = x.kind == BsvtfEntry::packet ? e / 2 : [&] {
      for (size_t i = 0; i < d->textures(); ++i)
        if (d->texture_block(i) == x.block && d->texture_group(i) == int(x.group)) return i;
      return size_t(0);
    }();
    Status s = x.kind == BsvtfEntry::packet ? d->read_packet(t).status() : d->decode_texture(t).status();
    if (!s.ok()) {
      ++refused;
      EXPECT_EQ(s.code(), StatusCode::corrupt_data) << s.message();
      EXPECT_NE(s.message().find(bad), std::string::npos) << s.message();
    }
  }
  EXPECT_GT(refused, 20);  // deflate streams rarely survive three random byte changes
}

TEST(BsvtfCodec, MalformedTilePayloads) {
  auto g = bsvtf::Geometry::make(8, 8, 8, 4, 1).value();  // one 16 x 16 plane: 256 coefficients
  std::vector<float> out(g.tile_floats());
  const auto steps = std::vector<float>(64, 1.0f);
  std::vector<uint8_t> raw(g.tile_floats(), 0);
  EXPECT_TRUE(bsvtf::decode_residual(g, raw.data(), raw.size(), steps.data(), out.data()).ok());
  EXPECT_FALSE(bsvtf::decode_residual(g, raw.data(), raw.size() - 1, steps.data(), out.data()).ok());  // short
  raw.push_back(0);
  EXPECT_FALSE(bsvtf::decode_residual(g, raw.data(), raw.size(), steps.data(), out.data()).ok());  // left over
  std::vector<uint8_t> longvar(g.tile_floats() + 5, 0);
  for (int i = 0; i < 5; ++i) longvar[size_t(i)] = 0xFF;  // a varint beyond 32 bits
  EXPECT_FALSE(bsvtf::decode_residual(g, longvar.data(), longvar.size(), steps.data(), out.data()).ok());
  std::vector<uint8_t> z = bsvtf::deflate_bytes(std::vector<uint8_t>(100, 7)), o;
  EXPECT_TRUE(bsvtf::inflate_bytes(z.data(), z.size(), 100, o).ok());
  EXPECT_FALSE(bsvtf::inflate_bytes(z.data(), z.size(), 99, o).ok());
  EXPECT_FALSE(bsvtf::inflate_bytes(z.data(), z.size(), 101, o).ok());
  EXPECT_FALSE(bsvtf::inflate_bytes(z.data(), z.size() - 2, 100, o).ok());
}

TEST(BsvtfCorruptOffset, ColourModel13) {
  // A dfmf file with its own luminance offset (colour model 13, version 1.1): the offset is the
  // f32 before the two CRCs. A bad offset, a 1.0 file claiming model 13, and an 11 <-> 13 swap
  // (the header size then disagrees) are refused with the file's path.
  auto m = make_model(40, 24, 4, 0.1, 3, 11, {}, 0.125f);
  ASSERT_TRUE(m);
  const std::string good = tmp_path("o13.bsvtf"), bad = tmp_path("o13bad.bsvtf");
  ASSERT_TRUE(write_bsvtf(*m, BsvtfOptions{}, good, nullptr).ok());
  const Bytes bytes = slurp(good);
  ASSERT_EQ(get32(bytes, 44), 13u);
  const uint32_t hb = get32(bytes, 12);
  auto expect = [&](const Bytes& b, const std::string& needle) {
    spit(bad, b);
    auto r = BsvtfReader::open(bad);
    ASSERT_FALSE(r.ok()) << needle;
    EXPECT_EQ(r.status().code(), StatusCode::corrupt_data) << r.status().message();
    EXPECT_NE(r.status().message().find(bad), std::string::npos) << r.status().message();
    EXPECT_NE(r.status().message().find(needle), std::string::npos) << r.status().message();
  };
  for (float v : {0.0f, -1.0f, std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity()}) {
    Bytes b = bytes;
    uint32_t u;
    std::memcpy(&u, &v, 4);
    put32(b, hb - 12, u);
    fix_crcs(b);
    expect(b, "luminance offset");
  }
  Bytes b = bytes;
  b[10] = 0;  // minor version 0
  fix_crcs(b);
  expect(b, "version 1.1");
  b = bytes;
  put32(b, 44, 11);  // model 11: 4 header bytes too many
  fix_crcs(b);
  expect(b, "header_bytes");
  b = bytes;
  put32(b, 44, 12);
  fix_crcs(b);
  expect(b, "colour model 12");
}
