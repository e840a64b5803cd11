// A raw .btfc streamed in place (formats/btf_stream.h open_raw_chunks): mapped chunks hold the
// file's values, the mapped factorization equals the copying one bit for bit, and a NaN or a
// flipped bit in the file is an error naming it, whichever way the chunks are fetched, and
// also when processes each map only their own chunks (the CRC parts joined after pass 0).
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <iterator>
#include <limits>
#include <thread>
#include <vector>

#include "codecs/codec.h"
#include "codecs/fmf/fmf.h"
#include "codecs/fmf/ooc_fmf.h"
#include "codecs/fmf/ooc_svd.h"
#include "core/synth.h"
#include "formats/btf_io.h"
#include "formats/btf_stream.h"
#include "tests/thread_group.h"

using namespace btfc;

namespace {

std::string tmp_path(const std::string& name) { return ::testing::TempDir() + "/rawchunks_" + std::to_string(::getpid()) + "_" + name; }

Btf synth(int w, int h) {
  SynthOptions o;
  o.width = w, o.height = h;
  o.views = DirectionSet::single(dir_from_theta_phi(0.5, 1.0));
  o.views.dirs.push_back(dir_from_theta_phi(0.9, 2.0));
  return synthesize_btf(o).value();
}

// The same chunks unmapped (mappable() false): through read() + decode() (`via_load` false:
// what the mapped path replaces), or through load() (true: the pread fallback a source that
// cannot map takes; RawChunks reads straight into the float block, without a raw buffer).
class Unmapped final : public ChunkSource {
 public:
  Unmapped(const ChunkSource& s, bool via_load) : m_s(s), m_load(via_load) {}
  size_t rows() const override { return m_s.rows(); }
  size_t num_chunks() const override { return m_s.num_chunks(); }
  size_t chunk_first(size_t c) const override { return m_s.chunk_first(c); }
  size_t chunk_count(size_t c) const override { return m_s.chunk_count(c); }
  size_t raw_bytes(size_t c) const override { return m_s.raw_bytes(c); }
  Status read(size_t c, void* raw) const override { return m_s.read(c, raw); }
  Status decode(size_t c, const void* raw, float* dst) const override { return m_s.decode(c, raw, dst); }
  Status load(size_t c, void* raw, float* dst) const override {
    return m_load ? m_s.load(c, raw, dst) : ChunkSource::load(c, raw, dst);  // the latter: read() + decode()
  }
  size_t raw_buffer_bytes(size_t c) const override { return m_load ? m_s.raw_buffer_bytes(c) : m_s.raw_bytes(c); }
  Status finish_first_pass(Collective& coll) const override { return m_s.finish_first_pass(coll); }

 private:
  const ChunkSource& m_s;
  bool m_load;
};

// Overwrites the first occurrence of `marker`'s bytes in the file with `value`'s.
void patch_float(const std::string& path, float marker, float value) {
  std::fstream io(path, std::ios::in | std::ios::out | std::ios::binary);
  std::string bytes{std::istreambuf_iterator<char>(io), {}};
  const size_t at = bytes.find(std::string(reinterpret_cast<const char*>(&marker), 4));
  ASSERT_NE(at, std::string::npos);
  io.clear();
  io.seekp(std::streamoff(at));
  io.write(reinterpret_cast<const char*>(&value), 4);
}

SvdOptions options() {
  SvdOptions opt;
  opt.max_rank = 6, opt.oversample = 4, opt.power_iters = 1, opt.method = SvdMethod::randomized;
  return opt;
}

}  // namespace

TEST(RawChunks, MappedChunksHoldTheFileAndFactorizeAsTheCopies) {
  const Btf b = synth(10, 7);
  const std::string path = tmp_path("a.btfc");
  ASSERT_TRUE(write_btf(b, path).ok());
  auto src = open_raw_chunks(path, 2);  // 4 chunks of 2 scan lines, the last one short
  ASSERT_TRUE(src.ok()) << src.status().message();
  const ChunkSource& s = *src.value();
  ASSERT_TRUE(s.mappable());
  ASSERT_EQ(s.num_chunks(), 4u);
  for (size_t c = 0; c < s.num_chunks(); ++c) {
    auto p = s.map(c);
    ASSERT_TRUE(p.ok()) << p.status().message();
    EXPECT_EQ(std::memcmp(*p, b.abrdf(s.chunk_first(c)), s.raw_bytes(c)), 0) << "chunk " << c;
    s.unmap(c, *p);
  }
  Collective one;
  auto mapped = fmf::streaming_svd(s, owned_chunks(s, 0, 1), options(), one);
  ASSERT_TRUE(mapped.ok()) << mapped.status().message();
  auto again = open_raw_chunks(path, 2);
  ASSERT_TRUE(again.ok());
  Unmapped copying(*again.value(), false);
  ASSERT_FALSE(copying.mappable());
  auto copied = fmf::streaming_svd(copying, owned_chunks(copying, 0, 1), options(), one);
  ASSERT_TRUE(copied.ok()) << copied.status().message();
  EXPECT_EQ(mapped->U, copied->U);
  EXPECT_EQ(mapped->SxV, copied->SxV);
  EXPECT_GT(mapped->S(0), 0.0f);
  // load() straight into the block: no raw buffer, the same chunks and the same factorization.
  auto third = open_raw_chunks(path, 2);
  ASSERT_TRUE(third.ok());
  Unmapped loading(*third.value(), true);
  EXPECT_EQ(loading.raw_buffer_bytes(0), 0u);
  for (size_t c = 0; c < loading.num_chunks(); ++c) {
    std::vector<float> block(loading.rows() * loading.chunk_count(c), -1.f);
    ASSERT_TRUE(loading.load(c, nullptr, block.data()).ok()) << "chunk " << c;
    EXPECT_EQ(std::memcmp(block.data(), b.abrdf(loading.chunk_first(c)), loading.raw_bytes(c)), 0) << "chunk " << c;
  }
  auto fourth = open_raw_chunks(path, 2);
  ASSERT_TRUE(fourth.ok());
  Unmapped loading2(*fourth.value(), true);
  auto loaded = fmf::streaming_svd(loading2, owned_chunks(loading2, 0, 1), options(), one);
  ASSERT_TRUE(loaded.ok()) << loaded.status().message();
  EXPECT_EQ(mapped->U, loaded->U);
  EXPECT_EQ(mapped->SxV, loaded->SxV);
  std::remove(path.c_str());
}

TEST(RawChunks, NaNAndFlippedBitAreErrorsWhetherMappedOrCopied) {
  Btf b = synth(10, 7);
  const float marker = 0.123456789f;
  const uint64_t texel = 6 * 10 + 3;  // (3, 6): in the last chunk
  b.abrdf(texel)[5] = marker;
  for (const char* kind : {"nan", "flip"}) {
    const std::string path = tmp_path(std::string(kind) + ".btfc");
    ASSERT_TRUE(write_btf(b, path).ok());
    patch_float(path, marker, std::string(kind) == "nan" ? std::numeric_limits<float>::quiet_NaN() : 0.5f);
    for (int way : {0, 1, 2}) {  // mapped, read() + decode(), load()
      const bool map = way == 0;
      auto src = open_raw_chunks(path, 2);
      ASSERT_TRUE(src.ok()) << src.status().message();
      Unmapped copying(*src.value(), false), loading(*src.value(), true);
      const ChunkSource& s = map ? *src.value() : way == 1 ? static_cast<const ChunkSource&>(copying) : loading;
      Collective one;
      auto r = fmf::streaming_svd(s, owned_chunks(s, 0, 1), options(), one);
      ASSERT_FALSE(r.ok()) << kind << " way " << way;
      EXPECT_EQ(r.status().code(), StatusCode::corrupt_data);
      const std::string want = std::string(kind) == "nan" ? "non-finite value at texel (3, 6)" : "CRC mismatch";
      EXPECT_NE(r.status().message().find(want), std::string::npos) << r.status().message();
      EXPECT_NE(r.status().message().find(path), std::string::npos) << r.status().message();
    }
    std::remove(path.c_str());
  }
}

// Three processes (threads), each mapping only its own chunks of its own open file, as btfc-mpi
// ranks do: the same factorization as one process, and a changed value anywhere (here in the
// middle process's range) is a CRC mismatch on every process.
TEST(RawChunks, ProcessesMappingTheirOwnChunksJoinTheCrc) {
  Btf b = synth(10, 7);
  const float marker = 0.987654321f;
  b.abrdf(3 * 10 + 4)[7] = marker;  // texel (4, 3): chunk 1 of 4, owned by the middle process
  const std::string path = tmp_path("mpi.btfc");
  ASSERT_TRUE(write_btf(b, path).ok());
  auto run = [&](int P, std::vector<Result<SvdResult>>& out) {
    test::run_group(P, [&](Collective& me, int r) {
      auto src = open_raw_chunks(path, 2);
      if (!src.ok()) return void(out[size_t(r)] = src.status());
      out[size_t(r)] = fmf::streaming_svd(*src.value(), owned_chunks(*src.value(), r, P), options(), me);
    });
  };
  std::vector<Result<SvdResult>> one(1, invalid_argument("not run")), three(3, invalid_argument("not run"));
  run(1, one);
  run(3, three);
  ASSERT_TRUE(one[0].ok()) << one[0].status().message();
  for (auto& r : three) ASSERT_TRUE(r.ok()) << r.status().message();
  EXPECT_LT((three[0]->U - one[0]->U).norm(), 1e-5f * one[0]->U.norm());
  EXPECT_LT((three[0]->SxV - one[0]->SxV).norm(), 1e-4f * one[0]->SxV.norm());

  patch_float(path, marker, 0.25f);
  run(3, three);
  for (auto& r : three) {
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.status().message().find("CRC mismatch"), std::string::npos) << r.status().message();
  }
  std::remove(path.c_str());
}

// A chunk's first-sight checks on several threads (CheckThreads, as color=dfmf's offset sweep
// asks for): the file's CRC still matches when clean and fails when one value changed, and of two
// NaNs in different threads' pieces the error names the first texel, as on one thread.
TEST(RawChunks, ChecksOnSeveralThreadsJoinTheCrcAndFindTheFirstNaN) {
  Btf b = synth(95, 95);  // one chunk of 95 lines: 9025 texels x 486 values, four pieces of 1.1 M values
  const float early = 0.111111f, late = 0.777777f;
  b.abrdf(20 * 95 + 5)[3] = early;  // texel (5, 20): the first piece
  b.abrdf(80 * 95 + 7)[9] = late;   // texel (7, 80): the last piece
  const std::string path = tmp_path("threads.btfc");
  auto sweep = [&](int threads) -> Status {
    auto src = open_raw_chunks(path, 95);
    if (!src.ok()) return src.status();
    const ChunkSource& s = *src.value();
    EXPECT_EQ(s.num_chunks(), 1u);
    EXPECT_GE(s.raw_bytes(0), size_t(4) << 22);
    const CheckThreads wide(threads);
    auto p = s.map(0);
    if (!p.ok()) return p.status();
    s.unmap(0, *p);
    Collective one;
    return s.finish_first_pass(one);
  };
  ASSERT_TRUE(write_btf(b, path).ok());
  for (int t : {1, 2, 4}) EXPECT_TRUE(sweep(t).ok()) << t << " threads: " << sweep(t).message();
  patch_float(path, late, std::numeric_limits<float>::quiet_NaN());
  for (int t : {1, 4}) {
    const Status s = sweep(t);
    EXPECT_NE(s.message().find("non-finite value at texel (7, 80)"), std::string::npos) << t << ": " << s.message();
  }
  patch_float(path, early, std::numeric_limits<float>::infinity());
  for (int t : {1, 4}) {
    const Status s = sweep(t);
    EXPECT_NE(s.message().find("non-finite value at texel (5, 20)"), std::string::npos) << t << ": " << s.message();
  }
  ASSERT_TRUE(write_btf(b, path).ok());
  patch_float(path, late, 0.5f);
  for (int t : {1, 2, 4}) {
    const Status s = sweep(t);
    EXPECT_NE(s.message().find("CRC mismatch"), std::string::npos) << t << ": " << s.message();
  }
  std::remove(path.c_str());
}

// color=dfmf's automatic offset out of core, from its sample of texels in the sweep that first
// sees (and checks) every chunk: the same offset as in core, and a NaN is an error naming the
// file and texel whether it lies in a sampled texel or in one the sample skips.
TEST(RawChunks, DfmfAutoOffsetReadsItsSampleAndNaNIsStillNamed) {
  Btf b = synth(70, 60);  // 4200 texels: 104 of them outside the offset's sample of 4096
  const std::vector<size_t> s = dfmf_offset_sample(b.desc().num_texels());
  size_t unsampled = 0;
  while (std::binary_search(s.begin(), s.end(), unsampled)) ++unsampled;
  const size_t sampled = s[2000];
  auto spec = resolve_spec("fmf:color=dfmf:rank=4:chroma_rank=2:oversample=4:power_iters=1:svd=randomized");
  ASSERT_TRUE(spec.ok());
  auto offset_of = [](const Model& m) {
    for (const auto& [k, v] : m.stats().numbers)
      if (k == "dfmf_offset") return v;
    return -1.0;
  };
  {
    const std::string path = tmp_path("dfmf_clean.btfc");
    ASSERT_TRUE(write_btf(b, path).ok());
    auto src = open_raw_chunks(path, 7);
    ASSERT_TRUE(src.ok()) << src.status().message();
    Context ctx;
    Collective one;
    auto st = encode_fmf_streamed(*src.value(), b.desc(), spec->second, ctx, one);
    ASSERT_TRUE(st.ok()) << st.status().message();
    auto in_core = spec->first->encode(b, spec->second, ctx);
    ASSERT_TRUE(in_core.ok()) << in_core.status().message();
    EXPECT_EQ(offset_of(*st->model), offset_of(*in_core.value()));
    EXPECT_GT(offset_of(*st->model), 0);
    std::remove(path.c_str());
  }
  const float marker = 0.123456789f;
  for (size_t texel : {sampled, unsampled}) {
    Btf bad = b;
    bad.abrdf(texel)[5] = marker;
    const std::string path = tmp_path("dfmf_nan.btfc");
    ASSERT_TRUE(write_btf(bad, path).ok());
    patch_float(path, marker, std::numeric_limits<float>::quiet_NaN());
    auto src = open_raw_chunks(path, 7);
    ASSERT_TRUE(src.ok()) << src.status().message();
    Context ctx;
    Collective one;
    auto st = encode_fmf_streamed(*src.value(), b.desc(), spec->second, ctx, one);
    ASSERT_FALSE(st.ok()) << texel;
    EXPECT_EQ(st.status().code(), StatusCode::corrupt_data);
    const std::string want = "non-finite value at texel (" + std::to_string(texel % 70) + ", " + std::to_string(texel / 70) + ")";
    EXPECT_NE(st.status().message().find(want), std::string::npos) << st.status().message();
    EXPECT_NE(st.status().message().find(path), std::string::npos) << st.status().message();
    std::remove(path.c_str());
  }
}
