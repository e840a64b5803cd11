// Golden files (tests/golden/, made by scripts/regen_golden.sh): one small model per codec as
// written by an earlier btfc, and its decoded values. A later change must keep them loading and
// decoding to the same values (else bump the codec's payload version and keep reading the old
// one), and every truncated prefix or single-byte flip must fail cleanly or decode identically.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <cstdio>
#include <fstream>
#include <iterator>

#include "codecs/codec.h"
#include "core/cl_runtime.h"
#include "core/container.h"
#include "tests/test_paths.h"

using namespace btfc;

namespace {

const std::string k_dir = std::string(BTFC_SOURCE_DIR) + "/tests/golden/";

// Every model file of tests/golden/ (NAME.btfc beside NAME.decoded.btfc; not the input): a new
// codec's golden file is tested as soon as scripts/regen_golden.sh has written it.
std::vector<std::string> golden_models() {
  std::vector<std::string> names;
  for (const auto& e : std::filesystem::directory_iterator(k_dir)) {
    const std::string f = e.path().filename().string();
    const std::string stem = f.substr(0, f.size() - std::min(f.size(), std::string(".btfc").size()));
    if (f.size() > 5 && f.ends_with(".btfc") && !f.ends_with(".decoded.btfc") && f != "input.btfc" &&
        std::filesystem::exists(k_dir + stem + ".decoded.btfc"))
      names.push_back(stem);
  }
  std::sort(names.begin(), names.end());
  return names;
}
const std::vector<std::string> k_models = golden_models();

std::vector<char> slurp(const std::string& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), {}};
}

Result<Btf> decode_file(const std::string& path) {
  BTFC_ASSIGN_OR_RETURN(ContainerReader rd, ContainerReader::open(path));
  BTFC_ASSIGN_OR_RETURN(auto model, load_model(rd));
  Btf out;
  BTFC_RETURN_IF_ERROR(model->decode_all(out));
  return out;
}

// Max |a - b| relative to max |b|; 1e-5 covers the OpenCL path's float rounding.
double rel_diff(const Btf& a, const Btf& b) {
  double d = 0, m = 1e-30;
  for (size_t i = 0; i < a.size(); ++i) d = std::max(d, double(std::fabs(a.data()[i] - b.data()[i]))), m = std::max(m, double(std::fabs(b.data()[i])));
  return d / m;
}

Btf expected(const std::string& name) {
  auto rd = ContainerReader::open(k_dir + name + ".decoded.btfc");
  EXPECT_TRUE(rd.ok()) << rd.status().message();
  auto b = load_raw_btf(rd.value());
  EXPECT_TRUE(b.ok());
  return std::move(b).value();
}

}  // namespace

TEST(Golden, EveryLibraryCodecHasAGoldenFile) {
  // The codecs of the library's table (codecs/registry.cpp); the test-only codec has no btfc
  // binary to write its file with.
  std::vector<std::string> have;
  for (const std::string& name : k_models) {
    auto rd = ContainerReader::open(k_dir + name + ".btfc");
    ASSERT_TRUE(rd.ok()) << rd.status().message();
    have.push_back(rd->codec().name);
  }
  for (const Codec* c : all_codecs()) {
    if (std::string(c->name()) == "toy") continue;
    EXPECT_NE(std::find(have.begin(), have.end(), c->name()), have.end())
        << c->name() << " has no golden file: run scripts/regen_golden.sh (it makes one per registered codec)";
  }
}

TEST(Golden, ModelsStillDecodeToTheirValues) {
  ASSERT_GE(k_models.size(), 5u);
  for (const std::string& name : k_models) {
    auto got = decode_file(k_dir + name + ".btfc");
    ASSERT_TRUE(got.ok()) << name << ": " << got.status().message();
    const Btf want = expected(name);
    ASSERT_EQ(got->size(), want.size()) << name;
    EXPECT_LE(rel_diff(got.value(), want), 1e-5) << name;
  }
}

TEST(Golden, TruncatedPrefixesFailCleanly) {
  ocl::set_device_choice(ocl::DeviceChoice::cpu);
  const std::string tmp = ::testing::TempDir() + "golden_trunc_" + std::to_string(::getpid()) + ".btfc";
  for (const std::string& name : k_models) {
    const std::vector<char> bytes = slurp(k_dir + name + ".btfc");
    ASSERT_GT(bytes.size(), 100u);
    for (size_t n = 0; n < bytes.size(); ++n) {
      std::ofstream(tmp, std::ios::binary).write(bytes.data(), std::streamsize(n));
      auto r = decode_file(tmp);
      ASSERT_FALSE(r.ok()) << name << " prefix " << n;
      ASSERT_NE(r.status().message().find(tmp), std::string::npos) << r.status().message();
    }
  }
  std::remove(tmp.c_str());
}

TEST(Golden, ByteFlipsFailOrDecodeIdentically) {
  ocl::set_device_choice(ocl::DeviceChoice::cpu);
  const std::string tmp = ::testing::TempDir() + "golden_flip_" + std::to_string(::getpid()) + ".btfc";
  for (const std::string& name : k_models) {
    std::vector<char> bytes = slurp(k_dir + name + ".btfc");
    const Btf want = expected(name);
    size_t failed = 0;
    for (size_t i = 0; i < bytes.size(); ++i) {
      bytes[i] = char(bytes[i] ^ 0xFF);
      std::ofstream(tmp, std::ios::binary).write(bytes.data(), std::streamsize(bytes.size()));
      bytes[i] = char(bytes[i] ^ 0xFF);
      auto r = decode_file(tmp);
      if (!r.ok()) {
        ++failed;
        continue;
      }
      ASSERT_EQ(rel_diff(r.value(), want), 0.0) << name << ": flip at byte " << i << " decoded differently";
    }
    // Every byte is covered by a checksum or a zero-padding check (docs/FORMAT.md).
    EXPECT_EQ(failed, bytes.size()) << name;
  }
  std::remove(tmp.c_str());
}
