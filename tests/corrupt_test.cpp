// Regression inputs (tests/corrupt/): every input that once crashed a fuzz target
// (tests/fuzz/, docs/robustness.md) or another hostile-input check, kept so the fix stays.
// Each must now give a clean error that names the file, never a crash, sanitizer report or
// huge allocation. By extension:
//   *.btfc  the container reader, then load_raw_btf / load_model and a bounded decode
//   *.btf   the Bonn readers (read_bonn_info and open_bonn_model)
//   *.spec  a spec string (resolve_spec)
// Image-set names (*.name) are checked by tests/io/corrupt_names_test.cpp (OpenImageIO side).
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <iterator>

#include "codecs/codec.h"
#include "core/container.h"
#include "formats/bonn/bonn_btf.h"
#include "tests/fuzz/fuzz_util.h"
#include "tests/test_paths.h"

using namespace btfc;
namespace fs = std::filesystem;

namespace {

const fs::path k_dir = fs::path(BTFC_SOURCE_DIR) / "tests" / "corrupt";

// First error on the way a user's file is read, or ok when everything succeeded.
Status open_btfc(const std::string& path) {
  BTFC_ASSIGN_OR_RETURN(ContainerReader rd, ContainerReader::open(path));
  BTFC_RETURN_IF_ERROR(rd.verify_all());
  if (rd.codec().name == "raw") {
    BTFC_ASSIGN_OR_RETURN(Btf b, load_raw_btf(rd));
    return b.check_finite(path);
  }
  BTFC_ASSIGN_OR_RETURN(auto m, load_model(rd));
  fuzz::exercise(*m);  // must not crash even if the loader accepted the file
  Btf out;
  DecodeRequest req;
  req.width = std::min(m->desc().width, 4), req.height = std::min(m->desc().height, 4);
  return m->decode(req, out);
}

Status open_bonn(const std::string& path) {
  auto info = read_bonn_info(path);
  auto m = open_bonn_model(path);
  if (info.ok() != m.ok()) return codec_error(path + ": read_bonn_info and open_bonn_model disagree");
  if (!m.ok()) return m.status();
  fuzz::exercise(*m.value());
  Btf out;
  DecodeRequest req;
  req.width = std::min(m.value()->desc().width, 4), req.height = std::min(m.value()->desc().height, 4);
  return m.value()->decode(req, out);
}

}  // namespace

TEST(Corrupt, EveryRegressionFileFailsCleanly) {
  ASSERT_TRUE(fs::is_directory(k_dir)) << k_dir;
  int checked = 0;
  for (const auto& e : fs::directory_iterator(k_dir)) {
    const std::string p = e.path().string(), ext = e.path().extension().string();
    Status s;
    if (ext == ".btfc") {
      s = open_btfc(p);
      if (!s.ok()) {
        EXPECT_NE(s.message().find(p), std::string::npos) << "error does not name the file: " << s.message();
      }
    } else if (ext == ".btf") {
      s = open_bonn(p);
      if (!s.ok()) {
        EXPECT_NE(s.message().find(p), std::string::npos) << "error does not name the file: " << s.message();
      }
    } else if (ext == ".spec") {
      std::ifstream in(p, std::ios::binary);
      const std::string text{std::istreambuf_iterator<char>(in), {}};
      auto r = resolve_spec(text);
      s = r.ok() ? Status() : r.status();
    } else {
      continue;  // README, *.name
    }
    EXPECT_FALSE(s.ok()) << p << ": accepted, expected a clean error";
    if (!s.ok()) {
      EXPECT_NE(s.code(), StatusCode::codec_error) << p << ": " << s.message();
    }
    ++checked;
  }
  // The directory is never empty: it starts with hand-made cases (see its README).
  EXPECT_GE(checked, 1);
}
