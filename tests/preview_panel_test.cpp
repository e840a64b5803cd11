// Labelled bench preview panels (codecs/preview_panel.h, issue 21): layout, labels drawn, the
// colour bar, and an error tile that is black for identical renders and lit where they differ.
#include <gtest/gtest.h>

#include <cmath>

#include "codecs/preview_panel.h"

namespace btfc {
namespace {

RgbImage ramp(int w, int h) {
  RgbImage im{w, h, std::vector<float>(size_t(w) * size_t(h) * 3)};
  for (int j = 0; j < h; ++j)
    for (int i = 0; i < w; ++i)
      for (int c = 0; c < 3; ++c) im.rgb[(size_t(j) * size_t(w) + size_t(i)) * 3 + size_t(c)] = 0.1f + 0.8f * float(i + j + c) / float(w + h);
  return im;
}

const float* at(const RgbImage& im, int x, int y) { return im.rgb.data() + (size_t(y) * size_t(im.width) + size_t(x)) * 3; }

// Pixels of rect r whose every channel is at least 0.99 (the white text).
int white_pixels(const RgbImage& im, const PanelRect& r) {
  int n = 0;
  for (int y = r.y; y < r.y + r.height; ++y)
    for (int x = r.x; x < r.x + r.width; ++x) n += at(im, x, y)[0] >= 0.99f && at(im, x, y)[1] >= 0.99f && at(im, x, y)[2] >= 0.99f;
  return n;
}

double max_in(const RgbImage& im, const PanelRect& r) {
  double m = 0;
  for (int y = r.y; y < r.y + r.height; ++y)
    for (int x = r.x; x < r.x + r.width; ++x)
      for (int c = 0; c < 3; ++c) m = std::max(m, double(at(im, x, y)[c]));
  return m;
}

TEST(preview, PanelLayoutAndLabels) {
  const RgbImage a = ramp(32, 24);
  auto p = preview_panel(a, a, 5, "demo fmf:rank=8");
  ASSERT_TRUE(p.ok()) << p.status().message();
  // 32 texels enlarged 4 x to 128: three tiles side by side, each render's aspect kept.
  EXPECT_EQ(p->scale, 4);
  for (int t = 0; t < 3; ++t) {
    EXPECT_EQ(p->tiles[t].width, 128);
    EXPECT_EQ(p->tiles[t].height, 96);
    EXPECT_LE(p->tiles[t].x + p->tiles[t].width, p->image.width);
    EXPECT_LE(p->tiles[t].y + p->tiles[t].height, p->image.height);
    if (t) {
      EXPECT_GT(p->tiles[t].x, p->tiles[t - 1].x + p->tiles[t - 1].width);  // a gap between tiles
    }
    // A label above each tile: white text pixels in its line.
    EXPECT_GT(white_pixels(p->image, p->labels[t]), 20) << t;
    EXPECT_LE(p->labels[t].y + p->labels[t].height, p->tiles[t].y);
  }
  EXPECT_EQ(p->image.width, 3 * 128 + 2 * 6 + 2 * 6);
  EXPECT_EQ(p->image.rgb.size(), size_t(p->image.width) * size_t(p->image.height) * 3);
  // The title line and the numbers under the bar are drawn too.
  EXPECT_GT(white_pixels(p->image, {0, 0, p->image.width, p->labels[0].y}), 40);
  EXPECT_GT(white_pixels(p->image, {p->bar.x, p->bar.y + p->bar.height, p->bar.width, p->image.height - p->bar.y - p->bar.height}), 20);
  // The colour bar: black at the left, white at the right, luminance rising along it.
  ASSERT_EQ(p->bar.width, 128);
  const int yb = p->bar.y + p->bar.height / 2;
  EXPECT_EQ(at(p->image, p->bar.x, yb)[0], 0.f);
  for (int c = 0; c < 3; ++c) EXPECT_EQ(at(p->image, p->bar.x + p->bar.width - 1, yb)[c], 1.f);
  double prev = -1;
  for (int x = p->bar.x; x < p->bar.x + p->bar.width; ++x) {
    const float* q = at(p->image, x, yb);
    const double s = q[0] + q[1] + q[2];
    EXPECT_GE(s, prev);
    prev = s;
  }
  // Identical renders: the error tile is black and the range printed is white / magnify.
  EXPECT_EQ(max_in(p->image, p->tiles[2]), 0.0);
  EXPECT_EQ(p->error_max, 0.0);
  EXPECT_NEAR(p->error_full_scale, p->white / 5, 1e-12);
  // The original and decoded tiles show the same picture.
  for (int y = 0; y < 96; y += 7)
    for (int x = 0; x < 128; x += 5)
      for (int c = 0; c < 3; ++c)
        EXPECT_EQ(at(p->image, p->tiles[0].x + x, p->tiles[0].y + y)[c], at(p->image, p->tiles[1].x + x, p->tiles[1].y + y)[c]);
}

TEST(preview, PanelErrorTileShowsDifferences) {
  const RgbImage a = ramp(16, 16);
  RgbImage b = a;
  // One texel off by a fifth of the display white: full scale (x 5) at that texel, 4 x 4 panel pixels.
  auto p0 = preview_panel(a, a, 5, "x");
  ASSERT_TRUE(p0.ok());
  const double white = p0->white;
  b.rgb[(5 * 16 + 7) * 3 + 1] += float(white / 5);
  auto p = preview_panel(a, b, 5, "x");
  ASSERT_TRUE(p.ok());
  EXPECT_EQ(p->scale, 8);
  EXPECT_NEAR(p->error_max, white / 5, 1e-6);
  const PanelRect& e = p->tiles[2];
  int lit = 0;
  for (int y = e.y; y < e.y + e.height; ++y)
    for (int x = e.x; x < e.x + e.width; ++x) lit += at(p->image, x, y)[0] > 0;
  EXPECT_EQ(lit, 8 * 8);  // exactly the one texel, enlarged
  const float* q = at(p->image, e.x + 7 * 8 + 3, e.y + 5 * 8 + 3);
  EXPECT_GT(q[0] + q[1] + q[2], 2.9f);  // full scale: white on the ramp
  // A small error shows dimmer, and still non-zero.
  b = a;
  b.rgb[(5 * 16 + 7) * 3] += float(white / 50);
  p = preview_panel(a, b, 5, "x");
  ASSERT_TRUE(p.ok());
  const float* r = at(p->image, e.x + 7 * 8 + 3, e.y + 5 * 8 + 3);
  EXPECT_GT(r[0], 0.f);
  EXPECT_LT(r[0] + r[1] + r[2], 1.f);
}

TEST(preview, PanelRefusesMismatchedRenders) {
  EXPECT_FALSE(preview_panel(ramp(8, 8), ramp(8, 9), 5, "x").ok());
  EXPECT_FALSE(preview_panel(RgbImage{}, RgbImage{}, 5, "x").ok());
  EXPECT_FALSE(preview_panel(ramp(8, 8), ramp(8, 8), 0, "x").ok());
}

TEST(preview, FontDrawsEveryCharacterOfASpec) {
  // Every character a codec spec or a number can contain has a glyph (unknown ones draw '?').
  RgbImage im{400, 10, std::vector<float>(400 * 10 * 3, 0.f)};
  const float white[3] = {1, 1, 1};
  const std::string s = "fmf:color=dfmf:rank=24,8 1.5e-03 (x5) |err| 100% lpca_a/b";
  EXPECT_EQ(draw_text(im, 0, 0, s, white), text_width(s));
  EXPECT_EQ(text_width(s), 6 * int(s.size()) - 1);
  // Glyphs differ (no two of '0'..'9' or 'A'..'Z' drawn alike) and '?' is only used for unknowns.
  std::vector<std::vector<float>> seen;
  for (char c : std::string("0123456789ABCDEFGHIJKLMNOPQRSTUVWXYZ.:=-+_/()|%,")) {
    RgbImage g{5, 7, std::vector<float>(5 * 7 * 3, 0.f)};
    draw_text(g, 0, 0, std::string(1, c), white);
    for (const auto& o : seen) EXPECT_NE(o, g.rgb) << c;
    seen.push_back(g.rgb);
  }
  RgbImage u{5, 7, std::vector<float>(5 * 7 * 3, 0.f)}, q = u;
  draw_text(u, 0, 0, "\x01", white);
  draw_text(q, 0, 0, "?", white);
  EXPECT_EQ(u.rgb, q.rgb);
}

}  // namespace
}  // namespace btfc
