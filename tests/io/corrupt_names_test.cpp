// Image-set names from tests/corrupt/*.name (one name per file, the exact bytes a fuzz target or
// a hostile archive produced): parse_image_name must reject each one with an error, and the
// view-folder check must answer, without crashing (see tests/corrupt/README.md).
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <iterator>

#include "formats/image_set.h"
#include "tests/test_paths.h"

namespace fs = std::filesystem;

TEST(CorruptNames, RejectedCleanly) {
  const fs::path dir = fs::path(BTFC_SOURCE_DIR) / "tests" / "corrupt";
  int checked = 0;
  for (const auto& e : fs::directory_iterator(dir)) {
    if (e.path().extension() != ".name") continue;
    std::ifstream in(e.path(), std::ios::binary);
    const std::string name{std::istreambuf_iterator<char>(in), {}};
    auto r = btfc::parse_image_name(name);
    EXPECT_FALSE(r.ok()) << e.path();
    (void)btfc::is_view_folder_name(name);
    ++checked;
  }
  EXPECT_GE(checked, 1);
}

// The length guard in parse_image_name sits at NAME_MAX: a 255-byte name still parses, 256 not.
TEST(CorruptNames, LengthGuardAtNameMax) {
  const std::string tail = "tl015_pl030_tv045_pv060.exr";
  const std::string ok = std::string(255 - tail.size() - 1, 'a') + "_" + tail;
  ASSERT_EQ(ok.size(), 255u);
  auto r = btfc::parse_image_name(ok);
  ASSERT_TRUE(r.ok()) << r.status().message();
  EXPECT_EQ(r->pl, 30);
  EXPECT_EQ(r->pv, 60);
  EXPECT_FALSE(btfc::parse_image_name("a" + ok).ok());
}
