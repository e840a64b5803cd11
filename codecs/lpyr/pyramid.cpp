// lpyr: YCbCr conversion and the Laplacian pyramid operators (paper section 3.1, eqs. 2-3).
// See lpyr_internal.h for the exact operators and lpyr.h for the codec.
#include <algorithm>
#include <cstring>

#include "codecs/lpyr/lpyr_internal.h"

namespace btfc::lpyr {

const char* const k_channel_names[3] = {"y", "cb", "cr"};

namespace {
// BT.601 luma weights; every other coefficient is derived from these two so that the inverse
// below is the exact inverse of the forward matrix (up to float rounding of the constants).
constexpr double k_kr = 0.299, k_kb = 0.114, k_kg = 1.0 - k_kr - k_kb;
constexpr double k_cb_div = 2.0 * (1.0 - k_kb), k_cr_div = 2.0 * (1.0 - k_kr);
constexpr float k_fwd[3][3] = {
    {float(k_kr), float(k_kg), float(k_kb)},
    {float(-k_kr / k_cb_div), float(-k_kg / k_cb_div), float((1.0 - k_kb) / k_cb_div)},
    {float((1.0 - k_kr) / k_cr_div), float(-k_kg / k_cr_div), float(-k_kb / k_cr_div)},
};
constexpr float k_inv[3][3] = {
    {1.0f, 0.0f, float(k_cr_div)},
    {1.0f, float(-k_kb * k_cb_div / k_kg), float(-k_kr * k_cr_div / k_kg)},
    {1.0f, float(k_cb_div), 0.0f},
};
}  // namespace

void rgb_to_ycbcr(const float* rgb, float* ycc) {
  for (int i = 0; i < 3; ++i) ycc[i] = k_fwd[i][0] * rgb[0] + k_fwd[i][1] * rgb[1] + k_fwd[i][2] * rgb[2];
}

void ycbcr_to_rgb(const float* ycc, float* rgb) {
  for (int i = 0; i < 3; ++i) rgb[i] = k_inv[i][0] * ycc[0] + k_inv[i][1] * ycc[1] + k_inv[i][2] * ycc[2];
}

std::vector<LevelSize> level_sizes(int width, int height, int lmax) {
  std::vector<LevelSize> s;
  LevelSize cur{width, height};
  for (int k = 0; k <= lmax; ++k) {
    s.push_back(cur);
    cur = {(cur.w + 1) / 2, (cur.h + 1) / 2};
  }
  return s;
}

int max_lmax(int width, int height) {
  int k = 0;
  while (width > 1 || height > 1) width = (width + 1) / 2, height = (height + 1) / 2, ++k;
  return k;
}

int auto_lmax(int width, int height, int components) {
  const int cap = max_lmax(width, height);
  int k = 0;
  size_t w = size_t(width), h = size_t(height);
  while (k < cap && w * h > 2 * size_t(components)) w = (w + 1) / 2, h = (h + 1) / 2, ++k;
  return k;
}

int bytes_lmax(int width, int height, size_t d, int ratio) {
  const int cap = max_lmax(width, height);
  int k = 0;
  size_t w = size_t(width), h = size_t(height);
  while (k < cap && d <= size_t(ratio) * (((w + 1) / 2) * ((h + 1) / 2))) w = (w + 1) / 2, h = (h + 1) / 2, ++k;
  return k;
}

void reduce(const float* src, int w, int h, size_t d, float* dst) {
  const int w2 = (w + 1) / 2, h2 = (h + 1) / 2;
  const long long n2 = (long long)w2 * h2;
#pragma omp parallel for schedule(static)
  for (long long t = 0; t < n2; ++t) {
    const int cx = 2 * int(t % w2), cy = 2 * int(t / w2);
    float* o = dst + size_t(t) * d;
    std::memset(o, 0, d * sizeof(float));
    for (int dy = -1; dy <= 1; ++dy) {
      const int yy = std::clamp(cy + dy, 0, h - 1);
      for (int dx = -1; dx <= 1; ++dx) {
        const int xx = std::clamp(cx + dx, 0, w - 1);
        const float* s = src + (size_t(xx) + size_t(w) * size_t(yy)) * d;
        for (size_t r = 0; r < d; ++r) o[r] += s[r];
      }
    }
    for (size_t r = 0; r < d; ++r) o[r] *= 1.0f / 9.0f;
  }
}

void subtract_up(float* f, int w, int h, size_t d, const float* next) {
  const int w2 = (w + 1) / 2;
  const long long n = (long long)w * h;
#pragma omp parallel for schedule(static)
  for (long long t = 0; t < n; ++t) {
    const int x = int(t % w), y = int(t / w);
    const float* s = next + (size_t(x / 2) + size_t(w2) * size_t(y / 2)) * d;
    float* o = f + size_t(t) * d;
    for (size_t r = 0; r < d; ++r) o[r] -= s[r];
  }
}

}  // namespace btfc::lpyr
