#include "codecs/preview_panel.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <vector>

namespace btfc {
namespace {

// 5 x 7 glyphs, written by hand for these panels: 7 rows top to bottom, bit 4 = leftmost column.
// No Debian font library fits: OpenImageIO's render_text needs FreeType and a font file found at
// run time (a different font, or none, on another machine), and the panels only need upper
// case, digits and the punctuation of codec specs and numbers.
struct Glyph {
  char c;
  uint8_t rows[7];
};
constexpr Glyph k_font[] = {
    {' ', {0, 0, 0, 0, 0, 0, 0}},
    {'0', {0x0E, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0E}},
    {'1', {0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E}},
    {'2', {0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F}},
    {'3', {0x1F, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0E}},
    {'4', {0x02, 0x06, 0x0A, 0x12, 0x1F, 0x02, 0x02}},
    {'5', {0x1F, 0x10, 0x1E, 0x01, 0x01, 0x11, 0x0E}},
    {'6', {0x06, 0x08, 0x10, 0x1E, 0x11, 0x11, 0x0E}},
    {'7', {0x1F, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08}},
    {'8', {0x0E, 0x11, 0x11, 0x0E, 0x11, 0x11, 0x0E}},
    {'9', {0x0E, 0x11, 0x11, 0x0F, 0x01, 0x02, 0x0C}},
    {'A', {0x0E, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11}},
    {'B', {0x1E, 0x11, 0x11, 0x1E, 0x11, 0x11, 0x1E}},
    {'C', {0x0E, 0x11, 0x10, 0x10, 0x10, 0x11, 0x0E}},
    {'D', {0x1C, 0x12, 0x11, 0x11, 0x11, 0x12, 0x1C}},
    {'E', {0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x1F}},
    {'F', {0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x10}},
    {'G', {0x0E, 0x11, 0x10, 0x17, 0x11, 0x11, 0x0F}},
    {'H', {0x11, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11}},
    {'I', {0x0E, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E}},
    {'J', {0x07, 0x02, 0x02, 0x02, 0x02, 0x12, 0x0C}},
    {'K', {0x11, 0x12, 0x14, 0x18, 0x14, 0x12, 0x11}},
    {'L', {0x10, 0x10, 0x10, 0x10, 0x10, 0x10, 0x1F}},
    {'M', {0x11, 0x1B, 0x15, 0x15, 0x11, 0x11, 0x11}},
    {'N', {0x11, 0x11, 0x19, 0x15, 0x13, 0x11, 0x11}},
    {'O', {0x0E, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E}},
    {'P', {0x1E, 0x11, 0x11, 0x1E, 0x10, 0x10, 0x10}},
    {'Q', {0x0E, 0x11, 0x11, 0x11, 0x15, 0x12, 0x0D}},
    {'R', {0x1E, 0x11, 0x11, 0x1E, 0x14, 0x12, 0x11}},
    {'S', {0x0F, 0x10, 0x10, 0x0E, 0x01, 0x01, 0x1E}},
    {'T', {0x1F, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04}},
    {'U', {0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E}},
    {'V', {0x11, 0x11, 0x11, 0x11, 0x11, 0x0A, 0x04}},
    {'W', {0x11, 0x11, 0x11, 0x15, 0x15, 0x15, 0x0A}},
    {'X', {0x11, 0x11, 0x0A, 0x04, 0x0A, 0x11, 0x11}},
    {'Y', {0x11, 0x11, 0x0A, 0x04, 0x04, 0x04, 0x04}},
    {'Z', {0x1F, 0x01, 0x02, 0x04, 0x08, 0x10, 0x1F}},
    {'.', {0, 0, 0, 0, 0, 0x0C, 0x0C}},
    {',', {0, 0, 0, 0, 0x0C, 0x04, 0x08}},
    {':', {0, 0x0C, 0x0C, 0, 0x0C, 0x0C, 0}},
    {';', {0, 0x0C, 0x0C, 0, 0x0C, 0x04, 0x08}},
    {'=', {0, 0, 0x1F, 0, 0x1F, 0, 0}},
    {'-', {0, 0, 0, 0x1F, 0, 0, 0}},
    {'+', {0, 0x04, 0x04, 0x1F, 0x04, 0x04, 0}},
    {'_', {0, 0, 0, 0, 0, 0, 0x1F}},
    {'/', {0, 0x01, 0x02, 0x04, 0x08, 0x10, 0}},
    {'(', {0x02, 0x04, 0x08, 0x08, 0x08, 0x04, 0x02}},
    {')', {0x08, 0x04, 0x02, 0x02, 0x02, 0x04, 0x08}},
    {'[', {0x0E, 0x08, 0x08, 0x08, 0x08, 0x08, 0x0E}},
    {']', {0x0E, 0x02, 0x02, 0x02, 0x02, 0x02, 0x0E}},
    {'<', {0x02, 0x04, 0x08, 0x10, 0x08, 0x04, 0x02}},
    {'>', {0x08, 0x04, 0x02, 0x01, 0x02, 0x04, 0x08}},
    {'|', {0x04, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04}},
    {'%', {0x18, 0x19, 0x02, 0x04, 0x08, 0x13, 0x03}},
    {'*', {0, 0x04, 0x15, 0x0E, 0x15, 0x04, 0}},
    {'#', {0x0A, 0x0A, 0x1F, 0x0A, 0x1F, 0x0A, 0x0A}},
    {'!', {0x04, 0x04, 0x04, 0x04, 0x04, 0, 0x04}},
    {'?', {0x0E, 0x11, 0x01, 0x02, 0x04, 0, 0x04}},
    {'\'', {0x04, 0x04, 0x08, 0, 0, 0, 0}},
    {'"', {0x0A, 0x0A, 0, 0, 0, 0, 0}},
    {'@', {0x0E, 0x11, 0x01, 0x0D, 0x15, 0x15, 0x0E}},
    {'&', {0x0C, 0x12, 0x14, 0x08, 0x15, 0x12, 0x0D}},
    {'~', {0, 0, 0x08, 0x15, 0x02, 0, 0}},
    {'^', {0x04, 0x0A, 0x11, 0, 0, 0, 0}},
    {'$', {0x04, 0x0F, 0x14, 0x0E, 0x05, 0x1E, 0x04}},
};

const Glyph& glyph(char c) {
  if (c >= 'a' && c <= 'z') c = char(c - 'a' + 'A');
  for (const Glyph& g : k_font)
    if (g.c == c) return g;
  for (const Glyph& g : k_font)
    if (g.c == '?') return g;
  return k_font[0];
}

constexpr int k_advance = 6, k_glyph_h = 7;
constexpr float k_background[3] = {0.05f, 0.05f, 0.06f};  // dark grey: white text stands out, and so do black render backgrounds
constexpr float k_text[3] = {1.f, 1.f, 1.f};

void fill(RgbImage& img, const PanelRect& r, const float rgb[3]) {
  for (int j = std::max(0, r.y); j < std::min(img.height, r.y + r.height); ++j)
    for (int i = std::max(0, r.x); i < std::min(img.width, r.x + r.width); ++i)
      std::copy(rgb, rgb + 3, img.rgb.data() + (size_t(j) * size_t(img.width) + size_t(i)) * 3);
}

// "1.23E-03": short, and only characters of the font.
std::string number(double v) {
  char s[32];
  std::snprintf(s, sizeof s, "%.3g", v);
  return s;
}

// `text` cut to at most `width` pixels, ".." marking the cut.
std::string fit(const std::string& text, int width, int scale) {
  if (text_width(text, scale) <= width) return text;
  std::string t = text;
  while (!t.empty() && text_width(t + "..", scale) > width) t.pop_back();
  return t + "..";
}

}  // namespace

void heat_color(double t, float rgb[3]) {
  const double e = std::clamp(t, 0.0, 1.0) * 3;
  rgb[0] = float(std::min(e, 1.0)), rgb[1] = float(std::clamp(e - 1, 0.0, 1.0)), rgb[2] = float(std::clamp(e - 2, 0.0, 1.0));
}

int text_width(const std::string& text, int scale) { return text.empty() ? 0 : (k_advance * int(text.size()) - 1) * scale; }

int draw_text(RgbImage& img, int x, int y, const std::string& text, const float rgb[3], int scale) {
  for (size_t k = 0; k < text.size(); ++k) {
    const Glyph& g = glyph(text[k]);
    for (int r = 0; r < k_glyph_h; ++r)
      for (int c = 0; c < 5; ++c)
        if (g.rows[r] & (0x10 >> c))
          fill(img, {x + (int(k) * k_advance + c) * scale, y + r * scale, scale, scale}, rgb);
  }
  return text_width(text, scale);
}

Result<PreviewPanel> preview_panel(const RgbImage& reference, const RgbImage& test, double magnify, const std::string& title) {
  const int w = reference.width, h = reference.height;
  if (w <= 0 || h <= 0 || reference.rgb.size() != size_t(w) * size_t(h) * 3) return invalid_argument("preview panel: empty reference render");
  if (test.width != w || test.height != h || test.rgb.size() != reference.rgb.size())
    return invalid_argument("preview panel: the renders differ in size");
  if (!(magnify > 0)) return invalid_argument("preview panel: magnify must be positive");
  PreviewPanel p;
  // Display scale: the reference's 99.5th-percentile luminance, as side_by_side.
  std::vector<float> y(size_t(w) * size_t(h));
  for (size_t k = 0; k < y.size(); ++k)
    y[k] = 0.2126f * reference.rgb[3 * k] + 0.7152f * reference.rgb[3 * k + 1] + 0.0722f * reference.rgb[3 * k + 2];
  std::sort(y.begin(), y.end());
  p.white = std::max(1e-12, double(y[std::min(y.size() - 1, size_t(0.995 * double(y.size())))]));
  p.error_full_scale = p.white / magnify;

  // Layout: 128-pixel tiles at least (labels fit), a 2x font from 256 on.
  p.scale = std::max(1, (128 + std::max(w, h) - 1) / std::max(w, h));
  const int tw = w * p.scale, th = h * p.scale, fs = tw >= 256 ? 2 : 1;
  const int m = 6, gap = 6, line = (k_glyph_h + 4) * fs;
  std::vector<std::string> title_lines;
  for (size_t a = 0, b; a <= title.size(); a = b + 1) {
    b = std::min(title.find('\n', a), title.size());
    title_lines.push_back(title.substr(a, b - a));
  }
  const int title_h = int(title_lines.size()) * line + m;
  p.image.width = m + 3 * tw + 2 * gap + m;
  const int tiles_y = title_h + line;
  const int bar_h = 10 * fs;
  p.image.height = tiles_y + th + 4 + line + bar_h + 3 * line + m;
  p.image.rgb.resize(size_t(p.image.width) * size_t(p.image.height) * 3);
  fill(p.image, {0, 0, p.image.width, p.image.height}, k_background);
  for (int t = 0; t < 3; ++t) {
    p.tiles[t] = {m + t * (tw + gap), tiles_y, tw, th};
    p.labels[t] = {p.tiles[t].x, title_h, tw, line};
  }
  p.bar = {p.tiles[2].x, tiles_y + th + 4 + line, tw, bar_h};

  // Tiles.
  for (int j = 0; j < th; ++j)
    for (int i = 0; i < tw; ++i) {
      const size_t k = (size_t(j / p.scale) * size_t(w) + size_t(i / p.scale)) * 3;
      double err = 0;
      float* px[3];
      for (int t = 0; t < 3; ++t)
        px[t] = p.image.rgb.data() + (size_t(p.tiles[t].y + j) * size_t(p.image.width) + size_t(p.tiles[t].x + i)) * 3;
      for (int c = 0; c < 3; ++c) {
        px[0][c] = float(std::clamp(reference.rgb[k + size_t(c)] / p.white, 0.0, 1.0));
        px[1][c] = float(std::clamp(test.rgb[k + size_t(c)] / p.white, 0.0, 1.0));
        err = std::max(err, double(std::abs(test.rgb[k + size_t(c)] - reference.rgb[k + size_t(c)])));
      }
      p.error_max = std::max(p.error_max, err);
      heat_color(err / p.error_full_scale, px[2]);
    }
  // The colour bar: the ramp left to right, framed in grey so its black end is visible.
  const float grey[3] = {0.3f, 0.3f, 0.3f};
  fill(p.image, {p.bar.x - 1, p.bar.y - 1, p.bar.width + 2, p.bar.height + 2}, grey);
  for (int i = 0; i < p.bar.width; ++i) {
    float c[3];
    heat_color(p.bar.width > 1 ? double(i) / double(p.bar.width - 1) : 1.0, c);
    fill(p.image, {p.bar.x + i, p.bar.y, 1, p.bar.height}, c);
  }

  // Text.
  const int pad = 2 * fs;
  for (size_t k = 0; k < title_lines.size(); ++k)
    draw_text(p.image, m, m + int(k) * line, fit(title_lines[k], p.image.width - 2 * m, fs), k_text, fs);
  const std::string heads[3] = {"original", "decoded", "|error| x" + number(magnify)};
  for (int t = 0; t < 3; ++t) draw_text(p.image, p.labels[t].x, p.labels[t].y + pad, fit(heads[t], tw, fs), k_text, fs);
  const int below = tiles_y + th + 4 + pad;
  for (int t = 0; t < 2; ++t) draw_text(p.image, p.tiles[t].x, below, fit("white = " + number(p.white), tw, fs), k_text, fs);
  draw_text(p.image, p.bar.x, below, fit("abs error scale", tw, fs), k_text, fs);
  const int nums = p.bar.y + p.bar.height + 2 + pad;
  draw_text(p.image, p.bar.x, nums, "0", k_text, fs);
  const std::string hi = number(p.error_full_scale);
  draw_text(p.image, p.bar.x + p.bar.width - text_width(hi, fs), nums, hi, k_text, fs);
  draw_text(p.image, p.bar.x, nums + line, fit("max " + number(p.error_max), tw, fs), k_text, fs);
  return p;
}

}  // namespace btfc
