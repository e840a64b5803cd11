// Image-set reader/writer tests: the real UBO2003 slice, the name parser, EXR/PNG round trips
// and the error messages (missing pair, size mismatch, not an image set).
#include "formats/image_set.h"

#include <OpenImageIO/imageio.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <random>
#include "tests/test_paths.h"

namespace btfc {
namespace {
namespace fs = std::filesystem;
constexpr double k_pi = 3.14159265358979323846;

const std::string k_slice = std::string(BTFC_DATA_DIR) + "/ubo2003_tv000_pv000_81lights";

double srgb_encode(double c) { return c <= 0.0031308 ? 12.92 * c : 1.055 * std::pow(c, 1.0 / 2.4) - 0.055; }
double srgb_decode(double c) { return c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4); }
Vec3 deg_dir(double t, double p) { return dir_from_theta_phi(t * k_pi / 180, p * k_pi / 180); }

// A fresh, empty scratch path per test; removed on destruction.
struct Scratch {
  fs::path root;
  Scratch() {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    root = fs::temp_directory_path() / ("btfc_io_" + std::to_string(getpid()) + "_" + info->name());
    fs::remove_all(root);
    fs::create_directories(root);
  }
  ~Scratch() { fs::remove_all(root); }
  std::string operator/(const std::string& s) const { return (root / s).string(); }
};

// Small BTF with lights/views already in (theta, phi) order, so a read gives the same order.
Btf make_btf(int w, int h, float lo, float hi, uint64_t seed) {
  BtfDesc d;
  d.width = w, d.height = h;
  d.lights.name = d.views.name = "custom";
  d.lights.dirs = {deg_dir(0, 0), deg_dir(15, 60), deg_dir(45, 340)};
  d.views.dirs = {deg_dir(0, 0), deg_dir(30, 90)};
  Btf b = Btf::create(d).value();
  std::mt19937_64 rng(seed);
  for (size_t i = 0; i < b.size(); ++i) b.data()[i] = lo + (hi - lo) * float(double(rng() >> 11) * 0x1.0p-53);
  return b;
}

void expect_same_dirs(const DirectionSet& a, const DirectionSet& b) {
  ASSERT_EQ(a.size(), b.size());
  for (size_t i = 0; i < a.size(); ++i) EXPECT_EQ(b.find(a.dirs[i]), int(i)) << "direction " << i;
}

TEST(ImageSet, ParsesBothNamingLayouts) {
  auto a = parse_image_name("00081 tl015 pl000 tv000 pv000.jpg");
  ASSERT_TRUE(a.ok()) << a.status().message();
  EXPECT_EQ(a->tl, 15); EXPECT_EQ(a->pl, 0); EXPECT_EQ(a->tv, 0); EXPECT_EQ(a->pv, 0);
  auto b = parse_image_name("/x/tv030_pv060/tl075_pl345_tv030_pv060.EXR");
  ASSERT_TRUE(b.ok()) << b.status().message();
  EXPECT_EQ(b->tl, 75); EXPECT_EQ(b->pl, 345); EXPECT_EQ(b->tv, 30); EXPECT_EQ(b->pv, 60);
  EXPECT_TRUE(parse_image_name("tl000_pl000_tv000_pv000.png").ok());
  EXPECT_TRUE(parse_image_name("06480 tl075 pl345 tv000 pv000.JPEG").ok());
  EXPECT_TRUE(parse_image_name("x_tl000 pl000_tv000 pv000.hdr").ok());  // separators mix freely
}

TEST(ImageSet, RejectsBadNames) {
  for (const char* bad : {"tl15 pl000 tv000 pv000.jpg", "tl015 pl000 tv000 pv000.tif", "tl015 pl000 tv000.jpg",
                          "tl400 pl000 tv000 pv000.jpg", "xtl015_pl000_tv000_pv000.png", "tl015-pl000-tv000-pv000.png",
                          "tl015_pl000_tv000_pv000.png.bak", "readme.txt", ""}) {
    auto r = parse_image_name(bad);
    EXPECT_FALSE(r.ok()) << bad;
    if (!r.ok()) {
      EXPECT_EQ(r.status().code(), StatusCode::invalid_argument);
    }
  }
}

TEST(ImageSet, ReadsRealUbo2003Slice) {
  if (!fs::is_directory(k_slice)) GTEST_SKIP() << k_slice << " absent";
  EXPECT_TRUE(is_image_set(k_slice));
  auto t0 = std::chrono::steady_clock::now();
  auto r = read_image_set(k_slice);
  double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  ASSERT_TRUE(r.ok()) << r.status().message();
  std::printf("read %s in %.3f s\n", r->desc().summary().c_str(), secs);
  const BtfDesc& d = r->desc();
  EXPECT_EQ(d.width, 256); EXPECT_EQ(d.height, 256); EXPECT_EQ(d.channels, 3);
  EXPECT_FALSE(d.hdr);
  EXPECT_EQ(d.lights.name, "ubo2003");
  expect_same_dirs(DirectionSet::ubo2003(), d.lights);
  ASSERT_EQ(d.num_views(), 1u);
  EXPECT_NEAR(d.views.dirs[0].z, 1.0f, 1e-6f);
  double theta, phi;
  dir_to_theta_phi(d.lights.dirs[1], theta, phi);
  EXPECT_NEAR(theta * 180 / k_pi, 15, 1e-4); EXPECT_NEAR(phi * 180 / k_pi, 0, 1e-4);

  double sum = 0, lo = 1e9, hi = -1e9;
  for (size_t i = 0; i < r->size(); ++i) {
    const double v = r->data()[i];
    sum += v, lo = std::min(lo, v), hi = std::max(hi, v);
  }
  const double mean = sum / double(r->size());
  std::printf("values in [%g, %g], mean %g\n", lo, hi, mean);
  EXPECT_GE(lo, 0.0); EXPECT_LE(hi, 1.0); EXPECT_LT(lo, hi);
  EXPECT_GT(mean, 0.005); EXPECT_LT(mean, 0.7);

  // Light 2 is tl015 pl060: compare with a direct 8-bit decode (also pins y = 0 = top row).
  auto in = OIIO::ImageInput::open(k_slice + "/00162 tl015 pl060 tv000 pv000.jpg");
  ASSERT_TRUE(in);
  std::vector<uint8_t> px(256 * 256 * 3);
  ASSERT_TRUE(in->read_image(0, 0, 0, 3, OIIO::TypeDesc::UINT8, px.data()));
  for (auto [x, y] : {std::pair{0, 0}, {255, 0}, {7, 200}, {128, 255}})
    for (int c = 0; c < 3; ++c)
      EXPECT_NEAR(r->at(x, y, 2, 0, c), srgb_decode(px[(y * 256 + x) * 3 + c] / 255.0), 1e-6) << x << "," << y;
}

TEST(ImageSet, RealSlicePngRoundTripIsExact) {
  if (!fs::is_directory(k_slice)) GTEST_SKIP() << k_slice << " absent";
  auto r = read_image_set(k_slice);
  ASSERT_TRUE(r.ok()) << r.status().message();
  BtfDesc d = r->desc();
  d.width = d.height = 16;  // a crop keeps the test fast
  Btf crop = Btf::create(d).value();
  for (int y = 0; y < 16; ++y)
    for (int x = 0; x < 16; ++x)
      std::copy_n(r->abrdf(size_t(x + 100) + 256 * size_t(y + 50)), d.abrdf_size(), crop.abrdf(size_t(x + 16 * y)));
  Scratch s;
  ASSERT_TRUE(write_image_set(crop, s / "out", ImageFormat::png).ok());
  EXPECT_TRUE(fs::exists(s / "out/tv000_pv000/tl075_pl345_tv000_pv000.png"));
  auto back = read_image_set(s / "out");
  ASSERT_TRUE(back.ok()) << back.status().message();
  EXPECT_EQ(back->desc().lights.name, "ubo2003");
  ASSERT_EQ(back->size(), crop.size());
  for (size_t i = 0; i < crop.size(); ++i) ASSERT_EQ(back->data()[i], crop.data()[i]) << i;  // 8 bit -> 8 bit
}

TEST(ImageSet, ExrRoundTripWithinHalfPrecision) {
  Btf b = make_btf(5, 4, 0.0f, 3.0f, 7);
  Scratch s;
  Status w = write_image_set(b, s / "exr/", ImageFormat::exr);  // trailing slash is fine
  ASSERT_TRUE(w.ok()) << w.message();
  EXPECT_TRUE(fs::exists(s / "exr/tv030_pv090/tl045_pl340_tv030_pv090.exr"));
  EXPECT_FALSE(fs::exists(s / ("exr.tmp-" + std::to_string(getpid()))));
  EXPECT_TRUE(is_image_set(s / "exr"));
  auto r = read_image_set(s / "exr");
  ASSERT_TRUE(r.ok()) << r.status().message();
  EXPECT_TRUE(r->desc().hdr);
  EXPECT_EQ(r->desc().width, 5); EXPECT_EQ(r->desc().height, 4);
  expect_same_dirs(b.desc().lights, r->desc().lights);
  expect_same_dirs(b.desc().views, r->desc().views);
  ASSERT_EQ(r->size(), b.size());
  for (size_t i = 0; i < b.size(); ++i) ASSERT_NEAR(r->data()[i], b.data()[i], 1e-3 * b.data()[i] + 1e-7) << i;
}

TEST(ImageSet, ExrKeepsValuesBeyondHalfRange) {
  Btf b = make_btf(3, 3, 0.0f, 1e6f, 3);
  Scratch s;
  ASSERT_TRUE(write_image_set(b, s / "big", ImageFormat::exr).ok());
  auto r = read_image_set(s / "big");
  ASSERT_TRUE(r.ok()) << r.status().message();
  for (size_t i = 0; i < b.size(); ++i) ASSERT_EQ(r->data()[i], b.data()[i]) << i;  // stored as float
}

TEST(ImageSet, PngRoundTripWithinOneSrgbStep) {
  Btf b = make_btf(6, 3, 0.0f, 1.0f, 11);
  b.data()[0] = 1.5f;    // clamped to 1
  b.data()[1] = -0.25f;  // clamped to 0
  Scratch s;
  ASSERT_TRUE(write_image_set(b, s / "png", ImageFormat::png).ok());
  auto r = read_image_set(s / "png");
  ASSERT_TRUE(r.ok()) << r.status().message();
  EXPECT_FALSE(r->desc().hdr);
  EXPECT_EQ(r->data()[0], 1.0f);
  EXPECT_EQ(r->data()[1], 0.0f);
  for (size_t i = 2; i < b.size(); ++i)
    ASSERT_NEAR(srgb_encode(r->data()[i]), srgb_encode(b.data()[i]), 0.5 / 255 + 1e-6) << i;
}

TEST(ImageSet, WriterRefusesNonEmptyDirectoryAndUsesEmptyOne) {
  Btf b = make_btf(2, 2, 0.0f, 1.0f, 1);
  Scratch s;
  fs::create_directories(s / "full");
  { std::FILE* f = std::fopen((s / "full/x.txt").c_str(), "w"); std::fclose(f); }
  Status w = write_image_set(b, s / "full", ImageFormat::png);
  EXPECT_FALSE(w.ok());
  EXPECT_NE(w.message().find("full"), std::string::npos) << w.message();
  fs::create_directories(s / "empty");
  EXPECT_TRUE(write_image_set(b, s / "empty", ImageFormat::png).ok());
  EXPECT_TRUE(is_image_set(s / "empty"));
}

TEST(ImageSet, WriterRejectsDirectionsWithTheSameRoundedName) {
  Btf b = make_btf(2, 2, 0.0f, 1.0f, 1);
  BtfDesc d = b.desc();
  d.lights.dirs = {deg_dir(30, 10.2), deg_dir(30, 9.9)};
  Scratch s;
  Status w = write_image_set(Btf::create(d).value(), s / "dup", ImageFormat::exr);
  EXPECT_FALSE(w.ok());
  EXPECT_NE(w.message().find("round"), std::string::npos) << w.message();
  EXPECT_FALSE(fs::exists(s / "dup"));
}

TEST(ImageSet, MissingImageNamesThePair) {
  Btf b = make_btf(3, 2, 0.0f, 1.0f, 2);
  Scratch s;
  ASSERT_TRUE(write_image_set(b, s / "m", ImageFormat::png).ok());
  fs::remove(s / "m/tv030_pv090/tl015_pl060_tv030_pv090.png");
  auto r = read_image_set(s / "m");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::corrupt_data);
  EXPECT_NE(r.status().message().find("tl015 pl060 tv030 pv090"), std::string::npos) << r.status().message();
}

TEST(ImageSet, DuplicateImageIsAnError) {
  Btf b = make_btf(3, 2, 0.0f, 1.0f, 2);
  Scratch s;
  ASSERT_TRUE(write_image_set(b, s / "d", ImageFormat::png).ok());
  fs::copy_file(s / "d/tv000_pv000/tl000_pl000_tv000_pv000.png", s / "d/tv000_pv000/00000 tl000 pl000 tv000 pv000.png");
  auto r = read_image_set(s / "d");
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("two images"), std::string::npos) << r.status().message();
}

TEST(ImageSet, SizeMismatchNamesTheFile) {
  Btf b = make_btf(4, 4, 0.0f, 1.0f, 5);
  Scratch s;
  ASSERT_TRUE(write_image_set(b, s / "sz", ImageFormat::png).ok());
  const std::string bad = s / "sz/tv030_pv090/tl045_pl340_tv030_pv090.png";
  auto out = OIIO::ImageOutput::create(bad);
  ASSERT_TRUE(out);
  std::vector<uint8_t> px(5 * 4 * 3, 128);
  ASSERT_TRUE(out->open(bad, OIIO::ImageSpec(5, 4, 3, OIIO::TypeDesc::UINT8)));
  ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT8, px.data()));
  out->close();
  auto r = read_image_set(s / "sz");
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("tl045_pl340_tv030_pv090.png"), std::string::npos) << r.status().message();
  EXPECT_NE(r.status().message().find("5x4"), std::string::npos) << r.status().message();
}

TEST(ImageSet, CorruptImageNamesTheFile) {
  Btf b = make_btf(4, 4, 0.0f, 1.0f, 5);
  Scratch s;
  ASSERT_TRUE(write_image_set(b, s / "c", ImageFormat::png).ok());
  const std::string bad = s / "c/tv000_pv000/tl015_pl060_tv000_pv000.png";
  { std::FILE* f = std::fopen(bad.c_str(), "w"); std::fputs("not a png", f); std::fclose(f); }
  auto r = read_image_set(s / "c");
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("tl015_pl060_tv000_pv000.png"), std::string::npos) << r.status().message();
}

TEST(ImageSet, ReadsOneViewFolderAndIgnoresHiddenAndOtherFiles) {
  Btf b = make_btf(3, 2, 0.0f, 1.0f, 4);
  Scratch s;
  ASSERT_TRUE(write_image_set(b, s / "v", ImageFormat::exr).ok());
  const std::string view = s / "v/tv030_pv090";
  fs::copy_file(view + "/tl000_pl000_tv030_pv090.exr", view + "/._00000 tl000 pl000 tv030 pv090.exr");  // macOS fork
  { std::FILE* f = std::fopen((view + "/notes.txt").c_str(), "w"); std::fclose(f); }
  EXPECT_TRUE(is_image_set(view));
  auto r = read_image_set(view);
  ASSERT_TRUE(r.ok()) << r.status().message();
  EXPECT_EQ(r->desc().num_lights(), 3u);
  ASSERT_EQ(r->desc().num_views(), 1u);
  EXPECT_EQ(r->desc().views.find(b.desc().views.dirs[1]), 0);
  for (int y = 0; y < 2; ++y)
    for (int x = 0; x < 3; ++x)
      for (int l = 0; l < 3; ++l) EXPECT_NEAR(r->at(x, y, l, 0, 2), b.at(x, y, l, 1, 2), 2e-3);
}

TEST(ImageSet, WriterRejectsNonFiniteValuesAndLeavesNothing) {
  Btf b = make_btf(3, 2, 0.0f, 1.0f, 4);
  b.at(2, 1, 1, 1, 0) = std::nanf("");
  Scratch s;
  Status w = write_image_set(b, s / "nan", ImageFormat::exr);
  ASSERT_FALSE(w.ok());
  EXPECT_NE(w.message().find("tl015_pl060_tv030_pv090.exr"), std::string::npos) << w.message();
  EXPECT_NE(w.message().find("(2, 1)"), std::string::npos) << w.message();
  EXPECT_TRUE(fs::is_empty(s.root));  // neither the target nor the temp directory
}

TEST(ImageSet, NonImageSetDirectoryIsAClearError) {
  Scratch s;
  fs::create_directories(s / "plain/sub");
  { std::FILE* f = std::fopen((s / "plain/notes.txt").c_str(), "w"); std::fclose(f); }
  EXPECT_FALSE(is_image_set(s / "plain"));
  auto r = read_image_set(s / "plain");
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("not an image set"), std::string::npos) << r.status().message();
  EXPECT_NE(r.status().message().find("plain"), std::string::npos);

  EXPECT_FALSE(is_image_set(s / "nope"));
  auto missing = read_image_set(s / "nope");
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.status().code(), StatusCode::io_error);
  EXPECT_FALSE(is_image_set(s / "plain/notes.txt"));
  EXPECT_FALSE(read_image_set(s / "plain/notes.txt").ok());
}

}  // namespace
}  // namespace btfc
