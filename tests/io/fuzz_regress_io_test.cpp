// Image-set regression inputs of fuzz_image_set (tests/fuzz/fuzz_image_set.cpp), kept in
// tests/corrupt/*.imageset in the target's input layout (tests/fuzz/image_set_input.h: a flag
// byte, then named files). Each is unpacked into a fresh directory and read the way the target
// does (bit 0: --allow-partial; bit 1: read_image_set(path), else plan_image_set +
// read_image_set(plan)); each must fail with an error naming the set or one of its files,
// never crash. The memory limit is the fuzz targets' 64 MiB (tests/fuzz/fuzz_util.h), so a set
// whose images declare a huge size fails at the BTF's allocation, as it did under the fuzzer.
#include <gtest/gtest.h>
#include <stdlib.h>

#include <filesystem>
#include <fstream>
#include <iterator>

#include "core/limits.h"
#include "formats/image_set.h"
#include "tests/fuzz/image_set_input.h"
#include "tests/test_paths.h"

using namespace btfc;
namespace fs = std::filesystem;

TEST(FuzzRegressIo, ImageSetsFailCleanly) {
  const fs::path corrupt = fs::path(BTFC_SOURCE_DIR) / "tests" / "corrupt";
  std::string tmpl = (fs::temp_directory_path() / "btfc-imageset-regress-XXXXXX").string();
  ASSERT_NE(mkdtemp(tmpl.data()), nullptr);
  int checked = 0;
  set_memory_limit(size_t(64) << 20);
  for (const auto& e : fs::directory_iterator(corrupt)) {
    if (e.path().extension() != ".imageset") continue;
    std::ifstream in(e.path(), std::ios::binary);
    const std::string b{std::istreambuf_iterator<char>(in), {}};
    const std::string dir = tmpl + "/" + e.path().stem().string();
    fs::create_directory(dir);
    const uint8_t flags = fuzz::write_image_set_entries(reinterpret_cast<const uint8_t*>(b.data()), b.size(), dir);
    set_allow_partial_image_sets((flags & 1) != 0);
    Status s;
    if (flags & 2) {
      s = read_image_set(dir).status();
    } else {
      auto plan = plan_image_set(dir);
      s = plan.ok() ? read_image_set(plan.value()).status() : plan.status();
    }
    EXPECT_FALSE(s.ok()) << e.path() << ": accepted, expected a clean error";
    if (!s.ok()) {
      EXPECT_NE(s.message().find(dir), std::string::npos) << e.path() << ": error names neither the set nor a file: " << s.message();
    }
    ++checked;
  }
  set_allow_partial_image_sets(false);
  set_memory_limit(0);  // back to the default
  std::error_code ec;
  fs::remove_all(tmpl, ec);
  // No .imageset file yet is fine: the other regression tests need the folder, this one not.
  SUCCEED() << checked << " image sets checked";
}
