// 8 x 8 DCT and JPEG-like quantisation steps; see dct.h.
#include "core/dct.h"

#include <algorithm>
#include <cmath>

namespace btfc::dct {

const std::array<uint8_t, 64> k_zigzag = {0,  1,  8,  16, 9,  2,  3,  10, 17, 24, 32, 25, 18, 11, 4,  5,
                                          12, 19, 26, 33, 40, 48, 41, 34, 27, 20, 13, 6,  7,  14, 21, 28,
                                          35, 42, 49, 56, 57, 50, 43, 36, 29, 22, 15, 23, 30, 37, 44, 51,
                                          58, 59, 52, 45, 38, 31, 39, 46, 53, 60, 61, 54, 47, 55, 62, 63};

const std::array<uint8_t, 64> k_jpeg_luma = {16, 11, 10, 16, 24,  40,  51,  61,  12, 12, 14, 19, 26,  58,  60,  55,
                                             14, 13, 16, 24, 40,  57,  69,  56,  14, 17, 22, 29, 51,  87,  80,  62,
                                             18, 22, 37, 56, 68,  109, 103, 77,  24, 35, 55, 64, 81,  104, 113, 92,
                                             49, 64, 78, 87, 103, 121, 120, 101, 72, 92, 95, 98, 112, 100, 103, 99};

namespace {

// c[u][x] = a(u) cos((2x + 1) u pi / 16), a(0) = sqrt(1/8), a(u > 0) = sqrt(2/8): the rows of
// the orthonormal 8-point DCT-II matrix.
struct Table {
  double c[8][8];
  Table() {
    const double pi = 3.14159265358979323846;
    for (int u = 0; u < 8; ++u)
      for (int x = 0; x < 8; ++x) c[u][x] = (u == 0 ? std::sqrt(0.125) : 0.5) * std::cos((2 * x + 1) * u * pi / 16.0);
  }
};
const Table k_t;

}  // namespace

void fdct8x8(const float* in, int stride, double out[64]) {
  double tmp[8][8];  // rows transformed: tmp[y][u]
  for (int y = 0; y < 8; ++y)
    for (int u = 0; u < 8; ++u) {
      double s = 0;
      for (int x = 0; x < 8; ++x) s += k_t.c[u][x] * double(in[y * stride + x]);
      tmp[y][u] = s;
    }
  for (int v = 0; v < 8; ++v)
    for (int u = 0; u < 8; ++u) {
      double s = 0;
      for (int y = 0; y < 8; ++y) s += k_t.c[v][y] * tmp[y][u];
      out[v * 8 + u] = s;
    }
}

void idct8x8(const double in[64], float* out, int stride) {
  double tmp[8][8];  // columns inverted: tmp[y][u]
  for (int y = 0; y < 8; ++y)
    for (int u = 0; u < 8; ++u) {
      double s = 0;
      for (int v = 0; v < 8; ++v) s += k_t.c[v][y] * in[v * 8 + u];
      tmp[y][u] = s;
    }
  for (int y = 0; y < 8; ++y)
    for (int x = 0; x < 8; ++x) {
      double s = 0;
      for (int u = 0; u < 8; ++u) s += k_t.c[u][x] * tmp[y][u];
      out[y * stride + x] = float(s);
    }
}

std::array<float, 64> quant_steps(int quality, float range) {
  const int q = std::clamp(quality, 1, 100);
  const long scale = q < 50 ? 5000 / q : 200 - 2 * q;
  std::array<float, 64> s{};
  for (int k = 0; k < 64; ++k) {
    const long t = std::max(1L, (long(k_jpeg_luma[size_t(k)]) * scale + 50) / 100);
    s[size_t(k)] = float(double(range) / 255.0 * double(t));
  }
  return s;
}

}  // namespace btfc::dct
