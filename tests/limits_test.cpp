// Resource limits (core/limits.h): the process memory limit, BTFC_MAX_MEMORY, and the rule that a
// declared size over the limit fails *before* allocating, in Btf::create, in the decode path
// (Model::decode -> prepare_output), in load_raw_btf and in load_model.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdint>
#include <cstdlib>
#include <string>

#include "codecs/codec.h"
#include "core/container.h"
#include "core/limits.h"
#include "core/memory.h"
#include "core/synth.h"

using namespace btfc;

namespace {

// Restores the default limit when a test ends, whatever it set.
struct LimitGuard {
  ~LimitGuard() {
    unsetenv("BTFC_MAX_MEMORY");
    set_memory_limit(0);
  }
};

std::string tmp(const std::string& n) { return std::string(::testing::TempDir()) + "limits_" + std::to_string(getpid()) + "_" + n; }

Btf small_btf(int w, int h) {
  SynthOptions o;
  o.width = w, o.height = h;
  auto b = synthesize_btf(o);
  EXPECT_TRUE(b.ok()) << b.status().message();
  return std::move(b).value();
}

bool mentions_limit(const Status& s) { return s.message().find("memory limit") != std::string::npos; }

}  // namespace

TEST(Limits, ParseByteSize) {
  EXPECT_EQ(parse_byte_size("1024").value(), 1024u);
  EXPECT_EQ(parse_byte_size("512M").value(), size_t(512) << 20);
  EXPECT_EQ(parse_byte_size("4G").value(), size_t(4) << 30);
  EXPECT_EQ(parse_byte_size("4gb").value(), size_t(4) << 30);
  EXPECT_EQ(parse_byte_size("2T").value(), size_t(2) << 40);
  EXPECT_EQ(parse_byte_size("3k").value(), 3072u);
  for (const char* bad : {"", "-1", "G", "1.5G", "12Q", "4G!", " 4G", "99999999999999999999", "20000000T", "16777216T"})
    EXPECT_FALSE(parse_byte_size(bad).ok()) << bad;
}

TEST(Limits, EnvironmentSetsTheLimitAndBadValuesAreIgnored) {
  LimitGuard g;
  setenv("BTFC_MAX_MEMORY", "3M", 1);
  set_memory_limit(0);  // re-reads the environment
  EXPECT_EQ(memory_limit(), size_t(3) << 20);
  setenv("BTFC_MAX_MEMORY", "lots", 1);
  set_memory_limit(0);
  EXPECT_EQ(memory_limit(), default_memory_limit());
  set_memory_limit(12345);
  EXPECT_EQ(memory_limit(), 12345u);
}

TEST(Limits, BtfCreateRefusesBeforeAllocating) {
  LimitGuard g;
  set_memory_limit(size_t(1) << 20);
  BtfDesc d;
  d.lights = DirectionSet::ubo2003();
  d.views = DirectionSet::ubo2003();
  d.width = d.height = 8;  // 8*8*81*81*3*4 = 5.0 MB > 1 MiB
  auto r = Btf::create(d);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::invalid_argument);
  EXPECT_TRUE(mentions_limit(r.status())) << r.status().message();
  // A declared 330 GB BTF (allocating it would abort the test) fails the same way: the check
  // runs before any allocation.
  d.width = d.height = 1 << 11;
  auto huge = Btf::create(d);
  ASSERT_FALSE(huge.ok());
  EXPECT_TRUE(mentions_limit(huge.status())) << huge.status().message();
  d.width = d.height = 2;  // 157 KB fits
  EXPECT_TRUE(Btf::create(d).ok());
}

TEST(Limits, DecodeAndLoadFailOverTheLimit) {
  LimitGuard g;
  const Btf in = small_btf(12, 10);  // 12*10*81*81*3*4 = 9.4 MB decoded
  auto spec = resolve_spec("fmf:rank=2:svd=exact");
  ASSERT_TRUE(spec.ok());
  Context ctx;
  auto model = spec->first->encode(in, spec->second, ctx);
  ASSERT_TRUE(model.ok()) << model.status().message();
  const std::string mp = tmp("m.btfc"), rp = tmp("raw.btfc");
  ASSERT_TRUE(save_model(*model.value(), *spec->first, mp).ok());
  ASSERT_TRUE(save_raw_btf(in, rp).ok());

  set_memory_limit(size_t(4) << 20);  // the model (~0.2 MB) loads, its decoded BTF does not fit
  auto rd = ContainerReader::open(mp);
  ASSERT_TRUE(rd.ok());
  auto m = load_model(rd.value());
  ASSERT_TRUE(m.ok()) << m.status().message();
  Btf out;
  Status s = m.value()->decode_all(out);
  EXPECT_FALSE(s.ok());
  EXPECT_TRUE(mentions_limit(s)) << s.message();
  EXPECT_EQ(out.size(), 0u);  // nothing allocated
  DecodeRequest part;  // a region that fits still decodes: block-wise decoding under a limit
  part.width = 4, part.height = 4;
  EXPECT_TRUE(m.value()->decode(part, out).ok());

  auto raw = ContainerReader::open(rp);
  ASSERT_TRUE(raw.ok());
  auto rb = load_raw_btf(raw.value());
  ASSERT_FALSE(rb.ok());
  EXPECT_TRUE(mentions_limit(rb.status())) << rb.status().message();

  set_memory_limit(size_t(64) << 10);  // below the model's own tensors: load_model refuses
  auto m2 = load_model(rd.value());
  ASSERT_FALSE(m2.ok());
  EXPECT_TRUE(mentions_limit(m2.status())) << m2.status().message();
  EXPECT_NE(m2.status().message().find(mp), std::string::npos) << m2.status().message();

  set_memory_limit(0);  // default again: everything decodes
  EXPECT_TRUE(m.value()->decode_all(out).ok());
  EXPECT_TRUE(load_raw_btf(raw.value()).ok());
  std::remove(mp.c_str());
  std::remove(rp.c_str());
}

// Scratch memory (core/memory.h): below 2 MiB plain malloc, above it 2 MiB-aligned; touched or
// not, every byte is the caller's to write and read back, on the main thread and inside a
// parallel region (where the touch is serial).
TEST(Memory, PageBuffersHoldWhatIsWrittenTouchedOrNot) {
  for (size_t count : {size_t(1), size_t(1000), size_t(3) << 20}) {
    for (int touched = 0; touched < 2; ++touched) {
      auto check = [&] {
        float* p = touched ? static_cast<float*>(page_alloc_touched(count * sizeof(float))) : static_cast<float*>(page_alloc(count * sizeof(float)));
        ASSERT_NE(p, nullptr);
        if (count * sizeof(float) >= (size_t(2) << 20)) {
          EXPECT_EQ(reinterpret_cast<uintptr_t>(p) % (size_t(2) << 20), 0u);
        }
        for (size_t i = 0; i < count; ++i) p[i] = float(i % 977);
        size_t bad = 0;
        for (size_t i = 0; i < count; ++i) bad += p[i] != float(i % 977);
        EXPECT_EQ(bad, 0u) << count << " " << touched;
        PageFree{}(p);
      };
      check();
#pragma omp parallel num_threads(2)
      {
#pragma omp single
        check();
      }
    }
  }
  PageBuffer<double> b(size_t(1) << 20);
  page_touch(b.data(), (size_t(1) << 20) * sizeof(double) - 3);  // any length, not whole pages
  b.data()[0] = 1.0, b.data()[(size_t(1) << 20) - 1] = 2.0;
  EXPECT_EQ(b.data()[0] + b.data()[(size_t(1) << 20) - 1], 3.0);
}
