// Tests for the .btfc container (core/container.h, docs/FORMAT.md): round trips, byte-identical
// re-save, and hostile input (every truncation, every single-byte flip, absurd sizes).
#include "core/container.h"

#include <Imath/half.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>

namespace btfc {
namespace {

namespace fs = std::filesystem;
using Bytes = std::vector<uint8_t>;

class ContainerTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    s_dir = fs::temp_directory_path() / ("btfc-container-test-" + std::to_string(getpid()));
    fs::create_directories(s_dir);
  }
  static void TearDownTestSuite() { fs::remove_all(s_dir); }
  static std::string tmp(const std::string& name) { return (s_dir / name).string(); }
  static fs::path s_dir;
};
fs::path ContainerTest::s_dir;

Bytes read_bytes(const std::string& p) {
  std::ifstream f(p, std::ios::binary);
  return Bytes(std::istreambuf_iterator<char>(f), {});
}
void write_bytes(const std::string& p, const Bytes& b) {
  // Unlink first: on ext4, truncating a recently written file can block on writeback for
  // ~20 ms, which made the byte-flip sweep take seconds.
  std::remove(p.c_str());
  std::ofstream f(p, std::ios::binary | std::ios::trunc);
  f.write(reinterpret_cast<const char*>(b.data()), std::streamsize(b.size()));
}

// Little-endian helpers written independently of the implementation, to pin the format.
uint64_t get_le(const Bytes& b, size_t at, int n) {
  uint64_t v = 0;
  for (int i = 0; i < n; ++i) v |= uint64_t(b[at + size_t(i)]) << (8 * i);
  return v;
}
void put_le(Bytes& b, size_t at, uint64_t v, int n) {
  for (int i = 0; i < n; ++i) b[at + size_t(i)] = uint8_t(v >> (8 * i));
}
void append_le(Bytes& b, uint64_t v, int n) {
  b.resize(b.size() + size_t(n));
  put_le(b, b.size() - size_t(n), v, n);
}
// zlib's crc32 returns 0 (the initial value) for a null buffer, so skip empty inputs.
uint32_t crc_of(const uint8_t* p, size_t n, uint32_t crc = 0) { return n ? uint32_t(crc32(crc, p, uInt(n))) : crc; }

// A parsed file for chunk surgery: header and chunks; build() recomputes every CRC.
struct RawChunk {
  std::string type;
  uint32_t flags;
  Bytes payload;
};
struct RawFile {
  Bytes header;
  std::vector<RawChunk> chunks;

  static RawFile parse(const Bytes& b) {
    RawFile f;
    f.header.assign(b.begin(), b.begin() + 32);
    for (size_t pos = 32; pos < b.size();) {
      RawChunk c;
      c.type.assign(reinterpret_cast<const char*>(&b[pos]), 4);
      c.flags = uint32_t(get_le(b, pos + 4, 4));
      uint64_t size = get_le(b, pos + 8, 8);
      c.payload.assign(b.begin() + long(pos + 32), b.begin() + long(pos + 32 + size));
      pos += 32 + size + (16 - size % 16) % 16;
      f.chunks.push_back(std::move(c));
    }
    return f;
  }
  Bytes build() const {
    Bytes b = header;
    put_le(b, 28, crc_of(b.data(), 28), 4);
    for (const RawChunk& c : chunks) {
      size_t at = b.size();
      b.insert(b.end(), c.type.begin(), c.type.end());
      append_le(b, c.flags, 4);
      append_le(b, c.payload.size(), 8);
      append_le(b, 0, 4);  // reserved u32
      append_le(b, 0, 8);  // reserved u64
      append_le(b, crc_of(c.payload.data(), c.payload.size(), crc_of(&b[at], 28)), 4);
      b.insert(b.end(), c.payload.begin(), c.payload.end());
      b.resize(b.size() + (16 - c.payload.size() % 16) % 16, 0);
    }
    return b;
  }
  RawChunk& chunk(const std::string& type, size_t nth = 0) {
    for (RawChunk& c : chunks)
      if (c.type == type && nth-- == 0) return c;
    throw std::runtime_error("no chunk " + type);
  }
};

BtfDesc make_desc() {
  BtfDesc d;
  d.width = 4, d.height = 3, d.channels = 3, d.hdr = true;
  d.lights.name = "custom";
  for (double t : {0.0, 0.3, 0.6, 0.9}) d.lights.dirs.push_back(dir_from_theta_phi(t, 2 * t));
  d.views.name = "two-views";
  d.views.dirs = {Vec3{0, 0, 1}, dir_from_theta_phi(0.5, 1.0)};
  return d;
}

const float k_view_data[4] = {1.5f, -2.0f, 3.25f, 1e-20f};

void fill_writer(ContainerWriter& w) {
  w.set_desc(make_desc());
  w.set_codec({"fmf", 3, "fmf:k=4,q=8", "9.9.9"});
  std::vector<float> u(12);
  for (size_t i = 0; i < u.size(); ++i) u[i] = float(i) * 0.5f - 2.0f;
  w.add_tensor(Tensor::from_f32("U", {3, 4}, u.data()));
  const uint32_t idx[5] = {0, 7, 0xffffffffu, 42, 3};
  w.add_tensor(Tensor::from_u32("idx", {5}, idx));
  Tensor h{"h", DType::f16, {2, 1}, {}};
  for (float v : {1.0f, -0.5f}) {
    uint16_t bits = Imath::half(v).bits();
    h.bytes.push_back(uint8_t(bits)), h.bytes.push_back(uint8_t(bits >> 8));
  }
  w.add_tensor(std::move(h));
  w.add_tensor_view("V", DType::f32, {2, 2}, k_view_data);
  w.set_stats("psnr = 41.5\ntime = 2\n");
}

// Opens and reads every tensor; the first error, or ok.
Status open_and_read_all(const std::string& path) {
  auto r = ContainerReader::open(path);
  if (!r.ok()) return r.status();
  BTFC_RETURN_IF_ERROR(r->verify_all());
  for (const TensorInfo& t : r->tensors()) {
    auto tr = r->read(t.name);
    if (!tr.ok()) return tr.status();
  }
  return {};
}

void expect_same_dirs(const DirectionSet& a, const DirectionSet& b) {
  EXPECT_EQ(a.name, b.name);
  ASSERT_EQ(a.size(), b.size());
  for (size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a.dirs[i].x, b.dirs[i].x);
    EXPECT_EQ(a.dirs[i].y, b.dirs[i].y);
    EXPECT_EQ(a.dirs[i].z, b.dirs[i].z);
  }
}

std::string small_file() {
  static std::string path;
  if (path.empty()) {
    path = (fs::temp_directory_path() / ("btfc-container-test-" + std::to_string(getpid())) / "small.btfc").string();
    ContainerWriter w;
    fill_writer(w);
    Status s = w.write(path);
    EXPECT_TRUE(s.ok()) << s.message();
  }
  return path;
}

TEST_F(ContainerTest, RoundTrip) {
  const std::string path = small_file();
  auto r = ContainerReader::open(path);
  ASSERT_TRUE(r.ok()) << r.status().message();
  const BtfDesc want = make_desc();
  EXPECT_EQ(r->desc().width, 4);
  EXPECT_EQ(r->desc().height, 3);
  EXPECT_EQ(r->desc().channels, 3);
  EXPECT_TRUE(r->desc().hdr);
  expect_same_dirs(r->desc().lights, want.lights);
  expect_same_dirs(r->desc().views, want.views);
  EXPECT_EQ(r->codec().name, "fmf");
  EXPECT_EQ(r->codec().payload_version, 3u);
  EXPECT_EQ(r->codec().spec, "fmf:k=4,q=8");
  EXPECT_EQ(r->codec().btfc_version, "9.9.9");
  EXPECT_EQ(r->stats(), "psnr = 41.5\ntime = 2\n");
  EXPECT_EQ(r->file_size(), fs::file_size(path));

  ASSERT_EQ(r->tensors().size(), 4u);
  const char* names[] = {"U", "idx", "h", "V"};  // owned tensors first, then views
  for (size_t i = 0; i < 4; ++i) EXPECT_EQ(r->tensors()[i].name, names[i]);
  for (const TensorInfo& t : r->tensors()) EXPECT_EQ(t.offset % 16, 0u) << t.name << " data not 16-byte aligned";

  auto u = r->read_checked("U", DType::f32, {3, 4});
  ASSERT_TRUE(u.ok()) << u.status().message();
  auto uf = u->to_f32();
  ASSERT_TRUE(uf.ok());
  for (size_t i = 0; i < 12; ++i) EXPECT_EQ(uf.value()[i], float(i) * 0.5f - 2.0f);

  auto idx = r->read("idx");
  ASSERT_TRUE(idx.ok());
  EXPECT_EQ(idx->dtype, DType::u32);
  EXPECT_EQ(idx->shape, (std::vector<uint64_t>{5}));
  const uint32_t want_idx[5] = {0, 7, 0xffffffffu, 42, 3};
  ASSERT_EQ(idx->bytes.size(), sizeof want_idx);
  EXPECT_EQ(std::memcmp(idx->bytes.data(), want_idx, sizeof want_idx), 0);

  auto h = r->read("h");
  ASSERT_TRUE(h.ok());
  auto hf = h->to_f32();
  ASSERT_TRUE(hf.ok());
  EXPECT_EQ(hf.value(), (std::vector<float>{1.0f, -0.5f}));

  float v[4];
  ASSERT_TRUE(r->read_into("V", v, sizeof v).ok());
  EXPECT_EQ(std::memcmp(v, k_view_data, sizeof v), 0);

  std::vector<std::string> types;
  for (const ChunkInfo& c : r->chunks()) types.push_back(c.type);
  EXPECT_EQ(types, (std::vector<std::string>{"DESC", "CODC", "TNSR", "TNSR", "TNSR", "TNSR", "STAT", "END "}));
  EXPECT_TRUE(r->verify_all().ok());
}

TEST_F(ContainerTest, HeaderBytesArePinned) {
  const Bytes b = read_bytes(small_file());
  ASSERT_GE(b.size(), 64u);
  EXPECT_EQ(std::memcmp(b.data(), "BTFC\r\n\x1a\n", 8), 0);
  EXPECT_EQ(get_le(b, 8, 2), 1u);    // major
  EXPECT_EQ(get_le(b, 10, 2), 0u);   // minor
  EXPECT_EQ(get_le(b, 12, 4), 32u);  // header_size
  EXPECT_EQ(get_le(b, 16, 8), 0u);   // flags
  EXPECT_EQ(get_le(b, 24, 4), 0u);   // reserved
  EXPECT_EQ(get_le(b, 28, 4), crc_of(b.data(), 28));
  EXPECT_EQ(std::memcmp(&b[32], "DESC", 4), 0);
  EXPECT_EQ(get_le(b, 36, 4), 1u);  // critical
  EXPECT_EQ(b.size() % 16, 0u);
  EXPECT_EQ(std::memcmp(&b[b.size() - 32], "END ", 4), 0);
  // RawFile::build is an independent writer of the documented layout: it must agree exactly.
  EXPECT_EQ(RawFile::parse(b).build(), b);
}

// The example file of docs/FORMAT.md, byte for byte. If this test fails, the format changed:
// bump the container version instead of editing these bytes.
const char* const k_golden_hex =
    "425446430d0a1a0a0100000020000000000000000000000000000000568cbd5c44455343010000003f00000000000000"
    "000000000000000000000000ce725b500200000002000000030000000000000006000000637573746f6d010000000000"
    "0000000000000000803f01000000760100000000000000000000000000803f00434f4443010000001f00000000000000"
    "000000000000000000000000407fbd9c03000000666d660100000007000000666d663a6b3d3105000000302e312e3000"
    "544e5352010000003800000000000000000000000000000000000000d7cad7d501000000550102000002000000000000"
    "000300000000000000000000000000000000803f0000004000004040000080400000a0400000c0400000000000000000"
    "53544154000000000400000000000000000000000000000000000000ddccc101613d310a000000000000000000000000"
    "454e44200100000000000000000000000000000000000000000000009ec350e9";

TEST_F(ContainerTest, GoldenBytes) {
  Bytes golden;
  for (const char* h = k_golden_hex; *h; h += 2) golden.push_back(uint8_t(std::stoi(std::string(h, 2), nullptr, 16)));
  ASSERT_EQ(golden.size(), 368u);

  BtfDesc d;
  d.width = 2, d.height = 2, d.channels = 3;
  d.lights = DirectionSet::single({0, 0, 1});
  d.views = DirectionSet::single({0, 0, 1}, "v");
  ContainerWriter w;
  w.set_desc(d);
  w.set_codec({"fmf", 1, "fmf:k=1", "0.1.0"});
  const float u[6] = {1, 2, 3, 4, 5, 6};
  w.add_tensor(Tensor::from_f32("U", {2, 3}, u));
  w.set_stats("a=1\n");
  const std::string p = tmp("golden.btfc");
  ASSERT_TRUE(w.write(p).ok());
  EXPECT_EQ(read_bytes(p), golden);

  write_bytes(p, golden);  // and the pinned bytes read back
  auto r = ContainerReader::open(p);
  ASSERT_TRUE(r.ok()) << r.status().message();
  EXPECT_EQ(r->desc().views.name, "v");
  EXPECT_EQ(r->codec().spec, "fmf:k=1");
  EXPECT_EQ(r->stats(), "a=1\n");
  auto t = r->read_checked("U", DType::f32, {2, 3});
  ASSERT_TRUE(t.ok());
  EXPECT_EQ(t->to_f32().value(), std::vector<float>(u, u + 6));
}

TEST_F(ContainerTest, SaveLoadSaveIsByteIdentical) {
  const std::string a = small_file(), b = tmp("resaved.btfc");
  auto r = ContainerReader::open(a);
  ASSERT_TRUE(r.ok()) << r.status().message();
  ContainerWriter w;
  w.set_desc(r->desc());
  w.set_codec(r->codec());
  for (const TensorInfo& t : r->tensors()) {
    auto tr = r->read(t.name);
    ASSERT_TRUE(tr.ok()) << tr.status().message();
    w.add_tensor(std::move(tr).value());
  }
  w.set_stats(r->stats());
  ASSERT_TRUE(w.write(b).ok());
  EXPECT_EQ(read_bytes(a), read_bytes(b));
  EXPECT_EQ(w.file_size(), fs::file_size(b));
}

TEST_F(ContainerTest, EveryTruncatedPrefixFails) {
  const Bytes full = read_bytes(small_file());
  const std::string p = tmp("trunc.btfc");
  for (size_t n = 0; n < full.size(); ++n) {
    write_bytes(p, Bytes(full.begin(), full.begin() + long(n)));
    Status s = open_and_read_all(p);
    ASSERT_FALSE(s.ok()) << "prefix of " << n << " bytes was accepted";
    EXPECT_EQ(s.message().rfind(p, 0), 0u) << s.message();
  }
}

TEST_F(ContainerTest, EveryByteFlipFails) {
  const Bytes full = read_bytes(small_file());
  const std::string p = tmp("flip.btfc");
  for (size_t i = 0; i < full.size(); ++i) {
    Bytes b = full;
    b[i] ^= 0xff;
    write_bytes(p, b);
    Status s = open_and_read_all(p);
    ASSERT_FALSE(s.ok()) << "flip at byte " << i << " was accepted";
    EXPECT_EQ(s.message().rfind(p, 0), 0u) << s.message();
  }
}

TEST_F(ContainerTest, TensorDataCorruptionIsCaughtOnRead) {
  Bytes b = read_bytes(small_file());
  auto r0 = ContainerReader::open(small_file());
  ASSERT_TRUE(r0.ok());
  const uint64_t at = r0->find("U")->offset + 5;
  b[at] ^= 0x01;
  const std::string p = tmp("crc.btfc");
  write_bytes(p, b);
  auto r = ContainerReader::open(p);
  ASSERT_TRUE(r.ok()) << "tensor data is only checked on read";
  auto t = r->read("U");
  ASSERT_FALSE(t.ok());
  EXPECT_EQ(t.status().code(), StatusCode::corrupt_data);
  EXPECT_EQ(t.status().message().rfind(p + ": chunk TNSR 'U': CRC mismatch", 0), 0u) << t.status().message();
  EXPECT_FALSE(r->verify_all().ok());
  EXPECT_TRUE(r->read("idx").ok());  // other tensors are unaffected
}

// Rewrites TNSR 'U' with the given dims (same data) and a valid CRC.
Bytes with_u_dims(const std::vector<uint64_t>& dims) {
  RawFile f = RawFile::parse(read_bytes(small_file()));
  RawChunk& c = f.chunk("TNSR");
  Bytes data(c.payload.end() - 48, c.payload.end());
  Bytes p;
  append_le(p, 1, 4);
  p.push_back('U');
  p.push_back(uint8_t(DType::f32));
  p.push_back(uint8_t(dims.size()));
  append_le(p, 0, 2);
  for (uint64_t d : dims) append_le(p, d, 8);
  p.resize(p.size() + (16 - p.size() % 16) % 16, 0);
  p.insert(p.end(), data.begin(), data.end());
  c.payload = p;
  return f.build();
}

TEST_F(ContainerTest, AbsurdSizesFailAtOpenBeforeAllocating) {
  const std::string p = tmp("absurd.btfc");
  write_bytes(p, with_u_dims({3, 4}));
  ASSERT_TRUE(open_and_read_all(p).ok()) << "surgery helper must reproduce a valid file";

  // Errors come from open(), which never allocates tensor data.
  write_bytes(p, with_u_dims({uint64_t(1) << 40, uint64_t(1) << 40}));
  auto r = ContainerReader::open(p);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::corrupt_data);
  EXPECT_EQ(r.status().message(), p + ": chunk TNSR 'U': dims 1099511627776x1099511627776 f32 overflow 64 bits");

  write_bytes(p, with_u_dims({uint64_t(1) << 20, uint64_t(1) << 20}));
  r = ContainerReader::open(p);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().message(), p + ": chunk TNSR 'U': dims 1048576x1048576 f32 need 4398046511104 bytes, chunk holds 48");

  write_bytes(p, with_u_dims({3, 5}));
  r = ContainerReader::open(p);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().message(), p + ": chunk TNSR 'U': dims 3x5 f32 need 60 bytes, chunk holds 48");

  write_bytes(p, with_u_dims({1, 1, 1, 1, 1, 1, 1, 1, 1}));
  r = ContainerReader::open(p);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("ndims 9 exceeds 8"), std::string::npos) << r.status().message();

  // A chunk size of 2^62 is rejected against the file length (before the CRC is even read).
  Bytes b = read_bytes(small_file());
  put_le(b, 32 + 8, uint64_t(1) << 62, 8);
  write_bytes(p, b);
  r = ContainerReader::open(p);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find(p + ": chunk DESC at offset 32: size 4611686018427387904"), std::string::npos)
      << r.status().message();

  // A direction count of 2^32-1 in a CRC-valid DESC is bounded by the payload.
  RawFile f = RawFile::parse(read_bytes(small_file()));
  Bytes& d = f.chunk("DESC").payload;
  const size_t count_at = 16 + 4 + get_le(d, 16, 4);
  put_le(d, count_at, 0xffffffffu, 4);
  write_bytes(p, f.build());
  r = ContainerReader::open(p);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("chunk DESC at offset 32: light set count 4294967295"), std::string::npos)
      << r.status().message();

  // A string length of 2^32-1.
  f = RawFile::parse(read_bytes(small_file()));
  put_le(f.chunk("CODC").payload, 0, 0xffffffffu, 4);
  write_bytes(p, f.build());
  r = ContainerReader::open(p);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("codec name length 4294967295 exceeds 65536"), std::string::npos)
      << r.status().message();
}

TEST_F(ContainerTest, TrailingBytesAfterEndFail) {
  const std::string p = tmp("trailing.btfc");
  for (size_t extra : {1, 16, 48}) {
    Bytes b = read_bytes(small_file());
    b.resize(b.size() + extra, 0);
    write_bytes(p, b);
    auto r = ContainerReader::open(p);
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.status().message().find("trailing bytes after the END chunk"), std::string::npos) << r.status().message();
  }
  // A valid chunk after END is trailing data too.
  RawFile f = RawFile::parse(read_bytes(small_file()));
  f.chunks.push_back(f.chunk("STAT"));
  write_bytes(p, f.build());
  EXPECT_FALSE(ContainerReader::open(p).ok());
}

TEST_F(ContainerTest, ChunkStructureRules) {
  const std::string p = tmp("structure.btfc");
  auto open_with = [&](RawFile f) {
    write_bytes(p, f.build());
    return ContainerReader::open(p);
  };
  const RawFile base = RawFile::parse(read_bytes(small_file()));
  ASSERT_TRUE(open_with(base).ok());

  RawFile f = base;
  f.chunks.insert(f.chunks.end() - 1, RawChunk{"XTRA", 0, Bytes{1, 2, 3}});
  auto r = open_with(f);
  ASSERT_TRUE(r.ok()) << "unknown non-critical chunks are skipped: " << r.status().message();
  EXPECT_EQ(r->chunks()[r->chunks().size() - 2].type, "XTRA");
  EXPECT_TRUE(r->verify_all().ok());

  f = base;
  f.chunks.insert(f.chunks.end() - 1, RawChunk{"XTRA", 1, Bytes{1, 2, 3}});
  r = open_with(f);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::unsupported);
  EXPECT_NE(r.status().message().find("chunk XTRA at offset"), std::string::npos) << r.status().message();

  f = base;
  f.chunks.erase(f.chunks.begin());  // no DESC
  r = open_with(f);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().message(), p + ": no DESC chunk");

  f = base;
  f.chunks.erase(f.chunks.begin() + 1);  // no CODC
  EXPECT_FALSE(open_with(f).ok());

  f = base;
  f.chunks.insert(f.chunks.begin() + 1, f.chunk("CODC"));
  r = open_with(f);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("second CODC chunk"), std::string::npos);

  f = base;
  f.chunks.insert(f.chunks.begin() + 2, f.chunk("TNSR"));
  r = open_with(f);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("chunk TNSR 'U': duplicate tensor name"), std::string::npos);

  f = base;
  f.chunk("STAT").flags = 1;  // known chunks have a fixed critical bit
  EXPECT_FALSE(open_with(f).ok());

  f = base;
  f.chunk("DESC").flags |= 2;  // reserved chunk flag bit
  EXPECT_FALSE(open_with(f).ok());
  f = base;
  f.chunk("DESC").flags |= 0x10000;  // optional chunk flag bit: ignored
  EXPECT_TRUE(open_with(f).ok());

  f = base;
  f.chunk("DESC").payload.push_back(0);  // DESC must be consumed exactly
  r = open_with(f);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("unexpected bytes after the last field"), std::string::npos);

  f = base;
  put_le(f.chunk("DESC").payload, 0, 0, 4);  // width 0: BtfDesc::validate rejects it
  r = open_with(f);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::corrupt_data);
  EXPECT_EQ(r.status().message().rfind(p + ": chunk DESC", 0), 0u) << r.status().message();

  f = base;
  f.chunk("END ").payload = {0};
  EXPECT_FALSE(open_with(f).ok());

  f = base;
  f.chunks.pop_back();  // no END
  r = open_with(f);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("no END chunk"), std::string::npos);
}

TEST_F(ContainerTest, HeaderVersionAndFlags) {
  const std::string p = tmp("header.btfc");
  const RawFile base = RawFile::parse(read_bytes(small_file()));
  RawFile f = base;
  put_le(f.header, 8, 2, 2);  // major 2
  write_bytes(p, f.build());
  auto r = ContainerReader::open(p);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::unsupported);

  f = base;
  put_le(f.header, 10, 7, 2);  // a newer minor is readable
  write_bytes(p, f.build());
  EXPECT_TRUE(ContainerReader::open(p).ok());

  f = base;
  put_le(f.header, 16, uint64_t(1) << 40, 8);  // optional flag (high 32 bits): ignored
  write_bytes(p, f.build());
  EXPECT_TRUE(ContainerReader::open(p).ok());

  f = base;
  put_le(f.header, 16, 4, 8);  // reserved flag (low 32 bits): error
  write_bytes(p, f.build());
  r = ContainerReader::open(p);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::corrupt_data);
  EXPECT_NE(r.status().message().find("reserved flag"), std::string::npos);

  for (size_t at : {12, 24}) {  // header_size and reserved
    f = base;
    f.header[at] ^= 1;
    write_bytes(p, f.build());
    EXPECT_FALSE(ContainerReader::open(p).ok()) << at;
  }
}

TEST_F(ContainerTest, OpenErrors) {
  auto r = ContainerReader::open(tmp("does-not-exist.btfc"));
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::io_error);
  EXPECT_EQ(r.status().message().rfind(tmp("does-not-exist.btfc") + ": ", 0), 0u);
  r = ContainerReader::open(s_dir.string());
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::io_error);
  write_bytes(tmp("text.btfc"), Bytes(64, 'x'));
  r = ContainerReader::open(tmp("text.btfc"));
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().message(), tmp("text.btfc") + ": not a .btfc file (bad magic)");
}

TEST_F(ContainerTest, ReadApiChecks) {
  auto r = ContainerReader::open(small_file());
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->find("nope"), nullptr);
  EXPECT_FALSE(r->read("nope").ok());
  EXPECT_FALSE(r->read_checked("U", DType::f16, {}).ok());
  EXPECT_FALSE(r->read_checked("U", DType::f32, {4, 3}).ok());
  EXPECT_TRUE(r->read_checked("U", DType::f32, {}).ok());
  float buf[12];
  EXPECT_EQ(r->read_into("U", buf, 44).code(), StatusCode::invalid_argument);
  EXPECT_TRUE(r->read_into("U", buf, 48).ok());
}

TEST_F(ContainerTest, ReaderMoveSemantics) {
  auto r = ContainerReader::open(small_file());
  ASSERT_TRUE(r.ok());
  ContainerReader a(std::move(r.value()));
  EXPECT_TRUE(a.read("U").ok());
  auto r2 = ContainerReader::open(small_file());
  ASSERT_TRUE(r2.ok());
  a = std::move(r2.value());  // closes a's old file, takes r2's
  EXPECT_TRUE(a.verify_all().ok());
  ContainerReader b(std::move(a));
  b = std::move(b);  // self-move keeps the file open
  EXPECT_TRUE(b.read("idx").ok());
}

TEST_F(ContainerTest, WriterFailureLeavesNoFile) {
  const std::string bad = tmp("no-such-dir/out.btfc");
  ContainerWriter w;
  fill_writer(w);
  Status s = w.write(bad);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.code(), StatusCode::io_error);
  EXPECT_EQ(s.message().rfind(bad + ": ", 0), 0u) << s.message();
  EXPECT_FALSE(fs::exists(bad));

  // Invalid content: refused before any file is created.
  const std::string p = tmp("invalid.btfc");
  ContainerWriter w2;
  fill_writer(w2);
  Tensor t = Tensor::from_f32("bad", {2}, k_view_data);
  t.shape = {3};
  w2.add_tensor(t);
  s = w2.write(p);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.code(), StatusCode::invalid_argument);
  EXPECT_EQ(s.message(), p + ": TNSR 'bad': dims 3 f32 need 12 bytes, tensor holds 8");
  ContainerWriter w3;
  fill_writer(w3);
  w3.add_tensor(Tensor::from_f32("U", {1}, k_view_data));
  EXPECT_FALSE(w3.write(p).ok());  // duplicate name
  ContainerWriter w4;
  w4.set_codec({"fmf", 1, "", ""});
  EXPECT_FALSE(w4.write(p).ok());  // invalid (empty) desc
  EXPECT_FALSE(fs::exists(p));

  // Failure in the middle of writing (file size limit): neither the file nor the temporary
  // remains. Run in a child so the limit does not leak into other tests.
  pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    signal(SIGXFSZ, SIG_IGN);
    rlimit lim{4096, 4096};
    setrlimit(RLIMIT_FSIZE, &lim);
    std::vector<float> big(1 << 16, 1.0f);
    ContainerWriter cw;
    fill_writer(cw);
    cw.add_tensor_view("big", DType::f32, {big.size()}, big.data());
    const std::string out = tmp("limited.btfc");
    Status cs = cw.write(out);
    bool clean = !fs::exists(out) && !fs::exists(out + ".tmp-" + std::to_string(getpid()));
    _exit(cs.code() == StatusCode::io_error && clean ? 0 : 1);
  }
  int status = 0;
  ASSERT_EQ(waitpid(child, &status, 0), child);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 0) << "size-limited write must fail cleanly";
  for (const auto& e : fs::directory_iterator(s_dir))
    EXPECT_EQ(e.path().string().find(".tmp-"), std::string::npos) << e.path();
}

TEST_F(ContainerTest, WriteReplacesExistingFile) {
  const std::string p = tmp("replace.btfc");
  write_bytes(p, Bytes(100, 'x'));
  ContainerWriter w;
  fill_writer(w);
  ASSERT_TRUE(w.write(p).ok());
  EXPECT_EQ(read_bytes(p), read_bytes(small_file()));
}

// A BTF of make_desc()'s directions, w x h texels, uniform values in [lo, hi) from `seed`.
Result<Btf> random_btf(int w, int h, unsigned seed, float lo, float hi) {
  BtfDesc d = make_desc();
  d.width = w, d.height = h;
  BTFC_ASSIGN_OR_RETURN(Btf btf, Btf::create(d));
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> dist(lo, hi);
  for (size_t i = 0; i < btf.size(); ++i) btf.data()[i] = dist(rng);
  return btf;
}

// A raw BTF written band by band (save_raw_btf_streamed: the tensor CRC goes into its header
// last) is the same file, byte for byte, as the one written from memory, for bands that do and
// do not divide the texel count; a failing band leaves no file behind and names its error.
TEST_F(ContainerTest, StreamedRawBtfIsTheSameFile) {
  auto btf = random_btf(5, 3, 9, -1.0f, 1e4f);
  ASSERT_TRUE(btf.ok());
  const BtfDesc& d = btf->desc();
  const std::string whole = tmp("whole.btfc");
  ASSERT_TRUE(save_raw_btf(btf.value(), whole).ok());
  for (uint64_t band : {uint64_t(1), uint64_t(4), uint64_t(15), uint64_t(100)}) {
    const std::string p = tmp("streamed.btfc");
    std::vector<uint64_t> seen;
    Status s = save_raw_btf_streamed(d, p, band, [&](uint64_t t0, uint64_t n, float* dst) -> Status {
      seen.push_back(t0);
      std::memcpy(dst, btf->abrdf(t0), size_t(n * d.abrdf_size()) * sizeof(float));
      return {};
    });
    ASSERT_TRUE(s.ok()) << s.message();
    EXPECT_EQ(read_bytes(p), read_bytes(whole)) << "band " << band;
    EXPECT_EQ(seen.size(), (15 + std::min<uint64_t>(band, 15) - 1) / std::min<uint64_t>(band, 15)) << band;
    auto r = ContainerReader::open(p);
    ASSERT_TRUE(r.ok());
    EXPECT_TRUE(r->verify_all().ok());
  }
  const std::string bad = tmp("failed.btfc");
  Status s = save_raw_btf_streamed(d, bad, 4, [&](uint64_t t0, uint64_t, float*) -> Status {
    return t0 >= 8 ? io_error("band at texel " + std::to_string(t0) + " failed (injected)") : Status{};
  });
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("band at texel 8 failed"), std::string::npos) << s.message();
  EXPECT_FALSE(fs::exists(bad));
  for (const auto& e : fs::directory_iterator(s_dir)) EXPECT_EQ(e.path().string().find("failed.btfc.tmp"), std::string::npos) << e.path();
}

TEST_F(ContainerTest, RawBtfRoundTrip) {
  auto btf = random_btf(5, 2, 7, 0.0f, 4.0f);
  ASSERT_TRUE(btf.ok());
  const BtfDesc& d = btf->desc();
  const std::string p = tmp("raw.btfc");
  ASSERT_TRUE(save_raw_btf(btf.value(), p).ok());

  auto r = ContainerReader::open(p);
  ASSERT_TRUE(r.ok()) << r.status().message();
  EXPECT_EQ(r->codec().name, "raw");
  EXPECT_EQ(r->codec().payload_version, 1u);
  EXPECT_EQ(r->codec().spec, "raw");
  EXPECT_EQ(r->codec().btfc_version, btfc_version());
  ASSERT_NE(r->find("data"), nullptr);
  EXPECT_EQ(r->find("data")->shape, (std::vector<uint64_t>{10, d.abrdf_size()}));
  auto back = load_raw_btf(r.value());
  ASSERT_TRUE(back.ok()) << back.status().message();
  EXPECT_EQ(back->desc().width, 5);
  expect_same_dirs(back->desc().lights, d.lights);
  expect_same_dirs(back->desc().views, d.views);
  ASSERT_EQ(back->size(), btf->size());
  EXPECT_EQ(std::memcmp(back->data(), btf->data(), btf->size() * sizeof(float)), 0);

  // Not raw: a model file is refused.
  auto m = ContainerReader::open(small_file());
  ASSERT_TRUE(m.ok());
  EXPECT_FALSE(load_raw_btf(m.value()).ok());

  // Raw codec but a "data" tensor whose shape disagrees with DESC.
  ContainerWriter w;
  w.set_desc(d);
  w.set_codec({"raw", 1, "raw", ""});
  std::vector<float> wrong(10 * d.abrdf_size() - 1);
  w.add_tensor(Tensor::from_f32("data", {wrong.size()}, wrong.data()));
  ASSERT_TRUE(w.write(p).ok());
  auto r2 = ContainerReader::open(p);
  ASSERT_TRUE(r2.ok());
  EXPECT_EQ(r2->codec().btfc_version, btfc_version()) << "an empty version is filled in by the writer";
  auto bad = load_raw_btf(r2.value());
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), StatusCode::corrupt_data);
  EXPECT_NE(bad.status().message().find("chunk TNSR 'data'"), std::string::npos);
}

TEST(TensorTest, Conversions) {
  const float vals[] = {0.0f, 1.0f, -2.5f, 65504.0f, 0.00006103515625f, 0.333251953125f};
  Tensor h{"h", DType::f16, {2, 3}, {}};
  for (float v : vals) {
    uint16_t bits = Imath::half(v).bits();
    h.bytes.push_back(uint8_t(bits)), h.bytes.push_back(uint8_t(bits >> 8));
  }
  auto f = h.to_f32();
  ASSERT_TRUE(f.ok());
  EXPECT_EQ(f.value(), std::vector<float>(std::begin(vals), std::end(vals)));  // all exact in half

  Tensor d{"d", DType::f64, {2}, Bytes(16)};
  const double dv[2] = {0.25, -1e10};
  std::memcpy(d.bytes.data(), dv, 16);
  auto df = d.to_f32();
  ASSERT_TRUE(df.ok());
  EXPECT_EQ(df.value(), (std::vector<float>{0.25f, -1e10f}));

  Tensor s = Tensor::from_f32("s", {}, vals + 2);  // scalar
  EXPECT_EQ(s.count(), 1u);
  EXPECT_EQ(s.to_f32().value(), (std::vector<float>{-2.5f}));

  const uint32_t u[3] = {1, 2, 3};
  Tensor ut = Tensor::from_u32("u", {3}, u);
  EXPECT_EQ(ut.bytes.size(), 12u);
  auto uf = ut.to_f32();
  ASSERT_FALSE(uf.ok());
  EXPECT_EQ(uf.status().code(), StatusCode::invalid_argument);

  h.bytes.pop_back();  // size disagrees with dims
  EXPECT_FALSE(h.to_f32().ok());

  EXPECT_EQ(dtype_size(DType::f16), 2u);
  EXPECT_EQ(dtype_size(DType::f64), 8u);
  EXPECT_STREQ(dtype_name(DType::u16), "u16");
  EXPECT_STRNE(btfc_version(), "");
}

}  // namespace
}  // namespace btfc

// Big buffers take the parallel CRC (pieces joined by crc32_combine): the same value as zlib's
// crc32 in one call, continuing a previous CRC, at sizes that do not split evenly; small ones
// libdeflate's CRC where the build has it (its vector loop, its tail bytes, at every alignment).
// An empty piece leaves the CRC as it was, even from a null pointer.
TEST(ContainerCrc, ParallelCrcEqualsZlib) {
  std::vector<uint8_t> buf((size_t(20) << 20) + 13);
  uint32_t x = 12345;
  for (auto& b : buf) b = uint8_t((x = x * 1103515245u + 12345u) >> 16);
  const uint32_t head = uint32_t(crc32(0, reinterpret_cast<const Bytef*>("head"), 4));
  EXPECT_EQ(btfc::crc32_update(head, nullptr, 0), head);
  EXPECT_EQ(btfc::crc32_update(head, buf.data(), 0), head);
  for (size_t off : {0, 1, 3, 7})
    for (size_t n : {size_t(1), size_t(15), size_t(16), size_t(63), size_t(64), size_t(255), size_t(4097)})
      EXPECT_EQ(btfc::crc32_update(head, buf.data() + off, n), uint32_t(crc32(head, buf.data() + off, uInt(n)))) << off << " " << n;
  for (size_t n : {size_t(100), size_t(8) << 20, buf.size()}) {
    const uint32_t seed = uint32_t(crc32(0, reinterpret_cast<const Bytef*>("head"), 4));
    EXPECT_EQ(btfc::crc32_update(seed, buf.data(), n), uint32_t(crc32(seed, buf.data(), uInt(n)))) << n;
  }
  // The split itself, any piece size and thread count: pieces in order, the last one short,
  // each piece seen once, nothing when there are no bytes.
  const size_t n = 100003;
  for (uint64_t per : {uint64_t(1) << 10, uint64_t(7777), uint64_t(n - 1), uint64_t(n), uint64_t(n + 5)})
    for (int threads : {1, 2, 3}) {
      std::vector<int> seen((n + per - 1) / per, 0);
      const uint32_t got = btfc::crc32_in_pieces(head, n, per, threads, [&](uint64_t i, uint64_t at, uint64_t bytes) {
        ++seen[size_t(i)];
        EXPECT_EQ(at, i * per);
        EXPECT_EQ(bytes, std::min<uint64_t>(per, n - at));
        return uint32_t(crc32(0, buf.data() + at, uInt(bytes)));
      });
      EXPECT_EQ(got, uint32_t(crc32(head, buf.data(), uInt(n)))) << per << " " << threads;
      EXPECT_EQ(std::count(seen.begin(), seen.end(), 1), std::ptrdiff_t(seen.size())) << per << " " << threads;
    }
  EXPECT_EQ(btfc::crc32_in_pieces(head, 0, 64, 2, [](uint64_t, uint64_t, uint64_t) { return 0u; }), head);
}
