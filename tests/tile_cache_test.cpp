// The offline tile-cache simulator (formats/bsvtf/tile_cache.h).
#include <gtest/gtest.h>

#include "formats/bsvtf/tile_cache.h"
#include "tests/bsvtf_fixture.h"

using namespace btfc;
using namespace bsvtf_test;

namespace {

// One file for the suite: 256 x 192 noisy eigen-textures (every tile differs from its parent,
// so w > 0 everywhere), 8 components = 2 virtual textures, 32-texel tiles = 4 levels.
const BsvtfReader& file() {
  static BsvtfReader r = [] {
    auto m = make_model(256, 192, 8, 0.3, 11);
    const std::string p = tmp_path("cache.bsvtf");
    BsvtfOptions o;
    o.tile = 32, o.quality = 85;
    EXPECT_TRUE(write_bsvtf(*m, o, p, nullptr).ok());
    return BsvtfReader::open(p).value();
  }();
  return r;
}

TileCacheOptions options(size_t slots, int frames = 16) {
  TileCacheOptions o;
  o.cache_tiles = slots;
  o.path.frames = frames, o.path.width = 96, o.path.height = 72;
  return o;
}

}  // namespace

TEST(TileCache, FeedbackFollowsTheCameraDistance) {
  const bsvtf::Geometry& g = file().geometry();
  CameraPathOptions p;
  p.frames = 21, p.width = 96, p.height = 72;
  int far_max = -1, near_max = -1;
  size_t far_hits = 0, near_hits = 0;
  for (const auto& [frame, lvl, hits] : {std::tuple{0, &far_max, &far_hits}, std::tuple{10, &near_max, &near_hits}}) {
    auto fb = feedback_image(g, p, frame).value();
    for (const FeedbackPixel& f : fb) {
      if (!f.hit) continue;
      ++*hits;
      EXPECT_GE(f.level, 0);
      EXPECT_LE(f.level, g.finest());
      EXPECT_LT(f.s, g.width);
      EXPECT_LT(f.t, g.height);
      *lvl = std::max(*lvl, f.level);
    }
  }
  // Far above, the 256-texel sample covers few of the 96 pixels: coarse levels only. Close up
  // and grazing, the sample fills the screen and the nearest pixels need the finest level.
  EXPECT_GT(far_hits, 100u);
  EXPECT_LE(far_max, 1);
  EXPECT_GT(near_hits, 2 * far_hits);
  EXPECT_EQ(near_max, g.finest());
  EXPECT_FALSE(feedback_image(g, CameraPathOptions{CameraPathOptions::Kind::fly, 0}, 0).ok());
}

TEST(TileCache, BiggerCacheNeverHurts) {
  auto sim = TileCacheSim::make(file()).value();
  ASSERT_EQ(sim.tiles(), 2u * (48 + 12 + 4 + 1));
  double prev_err = 1e30, prev_ssim = -1;
  for (size_t slots : {size_t(2), size_t(6), size_t(12), size_t(24), size_t(48), sim.tiles()}) {
    auto run = sim.run(options(slots)).value();
    ASSERT_EQ(run.frames.size(), 16u);
    EXPECT_LE(run.mean_error, prev_err + 1e-12) << slots << " slots";
    EXPECT_GE(run.mean_ssim, prev_ssim - 1e-12) << slots << " slots";
    for (const TileCacheFrame& f : run.frames) EXPECT_LE(f.resident, slots);
    prev_err = run.mean_error, prev_ssim = run.mean_ssim;
  }
  // A cache for every tile converges every frame: nothing differs from the converged render.
  auto all = sim.run(options(sim.tiles())).value();
  for (const TileCacheFrame& f : all.frames) {
    EXPECT_EQ(f.error, 0.0) << "frame " << f.frame;
    EXPECT_EQ(f.ssim, 1.0) << "frame " << f.frame;
  }
  // Two slots hold only the two level-0 tiles: a large error, far from converged.
  auto two = sim.run(options(2)).value();
  EXPECT_GT(two.mean_error, 0.05);
  EXPECT_LT(two.mean_ssim, 0.95);
}

TEST(TileCache, BytesStreamedAreAccounted) {
  const BsvtfReader& f = file();
  auto sim = TileCacheSim::make(f).value();
  // Unlimited cache: every tile a frame asks for and every packet is sent exactly once, plus
  // the header and directory, so the total is at most the file and at least header + packets.
  auto run = sim.run(options(sim.tiles(), 30)).value();
  uint64_t packets = 0;
  for (size_t t = 0; t < f.textures(); ++t) packets += f.entries()[bsvtf_packet_entry(t)].stored;
  EXPECT_LE(run.bytes, f.file_bytes());
  EXPECT_GE(run.bytes, f.header_bytes() + packets);
  for (size_t i = 1; i < run.frames.size(); ++i) EXPECT_GE(run.frames[i].bytes, run.frames[i - 1].bytes);
  EXPECT_EQ(run.frames.back().bytes, run.bytes);
  // A bandwidth limit spreads the same still view over frames; quality rises with the bytes.
  TileCacheOptions o = options(sim.tiles(), 40);
  o.path.kind = CameraPathOptions::Kind::still;
  o.bandwidth = 6000;
  auto slow = sim.run(o).value();
  uint64_t max_item = 0;
  for (const BsvtfEntry& e : f.entries()) max_item = std::max<uint64_t>(max_item, e.stored);
  for (size_t i = 1; i < slow.frames.size(); ++i) {
    // The first operation of a frame always goes (a swap + add moves up to two tiles).
    EXPECT_LE(slow.frames[i].bytes - slow.frames[i - 1].bytes, std::max(o.bandwidth, 2 * max_item)) << i;
    EXPECT_GE(slow.frames[i].ssim, slow.frames[i - 1].ssim - 0.02) << i;
  }
  EXPECT_LT(slow.frames.front().ssim, 0.9);
  EXPECT_EQ(slow.frames.back().ssim, 1.0);  // converged within 40 frames
}

TEST(TileCache, Deterministic) {
  auto sim = TileCacheSim::make(file()).value();
  auto a = sim.run(options(20)).value(), b = sim.run(options(20)).value();
  ASSERT_EQ(a.frames.size(), b.frames.size());
  for (size_t i = 0; i < a.frames.size(); ++i) {
    EXPECT_EQ(a.frames[i].error, b.frames[i].error);
    EXPECT_EQ(a.frames[i].bytes, b.frames[i].bytes);
    EXPECT_EQ(a.frames[i].adds, b.frames[i].adds);
  }
}

TEST(TileCache, RejectsBadOptions) {
  auto sim = TileCacheSim::make(file()).value();
  EXPECT_FALSE(sim.run(options(0)).ok());
  TileCacheOptions o = options(8);
  o.light = 99;
  EXPECT_FALSE(sim.run(o).ok());
}

TEST(TileCache, ConvergedImageIsTheModelShadedWithTheFilesOffset) {
  // A dfmf material the same at every texel: every pixel of the converged image, whatever level
  // and bilinear position it reads, shows the model's value at the shading (light, view), i.e.
  // the luminance of Model::eval there. The file is colour model 13 (offset 0.5, from the data
  // in a btfc encode): its Y' U' V' are shaded through that offset; Bonn's 1e-5 would put every
  // pixel off by about 0.5 / Y (about a third here).
  const int W = 96, H = 64;
  const float offset = 0.5f;
  const BtfDesc d = small_desc(W, H);
  const size_t rows = d.num_images();  // 10: 5 lights x 2 views
  // Per block: Y' U' V' = (a + b s_r) / sqrt(rows), s_r = +1 on even rows, -1 on odd ones (two
  // orthonormal columns):
  // Y + e in [1.5, 2.3], chroma a few hundredths.
  const float ab[3][2] = {{2.0f, 0.6f}, {0.1f, 0.05f}, {-0.08f, 0.04f}};
  std::vector<FmfFactors> blocks;
  for (int b = 0; b < 3; ++b) {
    FmfFactors f;
    f.name = std::string(1, "yuv"[b]);
    f.C = 2;
    for (size_t r = 0; r < rows; ++r) f.U.push_back(float(1 / std::sqrt(double(rows)))), f.U.push_back(float((r % 2 ? -1 : 1) / std::sqrt(double(rows))));
    for (int t = 0; t < W * H; ++t) f.SxV.push_back(ab[b][0]), f.SxV.push_back(ab[b][1]);
    f.S.assign(2, 1.0f);
    blocks.push_back(std::move(f));
  }
  auto m = make_fmf_model(d, 11, std::move(blocks), nullptr, nullptr, false, offset);
  ASSERT_TRUE(m.ok()) << m.status().message();
  const std::string p = tmp_path("uniform13.bsvtf");
  BsvtfOptions bo;
  bo.tile = 32;
  ASSERT_TRUE(write_bsvtf(**m, bo, p, nullptr).ok());
  auto rd = BsvtfReader::open(p);
  ASSERT_TRUE(rd.ok()) << rd.status().message();
  ASSERT_EQ(rd->color_model(), 13);
  auto sim = TileCacheSim::make(*rd);
  ASSERT_TRUE(sim.ok()) << sim.status().message();
  double worst = 0, spread_lo = 1e30, spread_hi = 0;
  for (auto [light, view] : {std::pair{-1, -1}, std::pair{3, 0}, std::pair{1, 1}}) {
    TileCacheOptions o = options(8, 8);
    o.light = light, o.view = view;
    float rgb[3];
    (*m)->eval(W / 3, H / 2, light >= 0 ? light : int(d.num_lights()) / 2, view >= 0 ? view : 0, rgb);
    const double want = 0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2];
    spread_lo = std::min(spread_lo, want), spread_hi = std::max(spread_hi, want);
    for (int frame : {0, 4}) {
      auto img = sim->converged_luminance(o, frame);
      ASSERT_TRUE(img.ok()) << img.status().message();
      ASSERT_EQ(img->size(), size_t(o.path.width) * size_t(o.path.height));
      size_t hits = 0;
      for (float v : *img)
        if (!std::isnan(v)) ++hits, worst = std::max(worst, std::abs(v - want) / want);
      EXPECT_GT(hits, img->size() / 10) << frame;
    }
  }
  std::printf("converged luminance of a uniform colour model 13 file: worst rel. error %.3g (shadings %.3f..%.3f)\n", worst, spread_lo, spread_hi);
  EXPECT_GT(spread_hi, 1.1 * spread_lo);  // the three shadings differ: light and view are honoured
  // Half-float packets and one quantised DC per tile: 1e-3 relative at most.
  EXPECT_LE(worst, 1e-3);
  TileCacheOptions bad = options(8, 8);
  bad.view = 2;
  EXPECT_FALSE(sim->converged_luminance(bad, 0).ok());
  EXPECT_FALSE(sim->converged_luminance(options(8, 8), 8).ok());  // past the path's frames
}
