#include "core/gpu_texture.h"

#include <Imath/half.h>

#include <algorithm>
#include <cmath>
#include <cstring>

namespace btfc::gpu {
namespace {

// GL enums (GLES 3.0 / GL 4.x), listed here so the manifest can name them without GL headers.
constexpr uint32_t GL_RED = 0x1903, GL_RG = 0x8227, GL_RGBA = 0x1908;
constexpr uint32_t GL_RED_INTEGER = 0x8D94, GL_RG_INTEGER = 0x8228, GL_RGBA_INTEGER = 0x8D99;
constexpr uint32_t GL_UNSIGNED_BYTE = 0x1401, GL_UNSIGNED_SHORT = 0x1403, GL_UNSIGNED_INT = 0x1405;
constexpr uint32_t GL_HALF_FLOAT = 0x140B, GL_FLOAT = 0x1406;

const FormatInfo k_formats[] = {
    {"r8_unorm", 9, 0x8229, GL_RED, GL_UNSIGNED_BYTE, 1, 1, false, false, true},
    {"rg8_unorm", 16, 0x822B, GL_RG, GL_UNSIGNED_BYTE, 2, 1, false, false, true},
    {"rgba8_unorm", 37, 0x8058, GL_RGBA, GL_UNSIGNED_BYTE, 4, 1, false, false, true},
    {"r8_uint", 13, 0x8232, GL_RED_INTEGER, GL_UNSIGNED_BYTE, 1, 1, false, true, false},
    {"r16_uint", 74, 0x8234, GL_RED_INTEGER, GL_UNSIGNED_SHORT, 1, 2, false, true, false},
    {"rg16_uint", 81, 0x823A, GL_RG_INTEGER, GL_UNSIGNED_SHORT, 2, 2, false, true, false},
    {"rgba16_uint", 95, 0x8D76, GL_RGBA_INTEGER, GL_UNSIGNED_SHORT, 4, 2, false, true, false},
    {"r32_uint", 98, 0x8236, GL_RED_INTEGER, GL_UNSIGNED_INT, 1, 4, false, true, false},
    {"rgba32_uint", 107, 0x8D70, GL_RGBA_INTEGER, GL_UNSIGNED_INT, 4, 4, false, true, false},
    {"r16f", 76, 0x822D, GL_RED, GL_HALF_FLOAT, 1, 2, true, false, false},
    {"rg16f", 83, 0x822F, GL_RG, GL_HALF_FLOAT, 2, 2, true, false, false},
    {"rgba16f", 97, 0x881A, GL_RGBA, GL_HALF_FLOAT, 4, 2, true, false, false},
    {"r32f", 100, 0x822E, GL_RED, GL_FLOAT, 1, 4, true, false, false},
    {"rg32f", 103, 0x8230, GL_RG, GL_FLOAT, 2, 4, true, false, false},
    {"rgba32f", 109, 0x8814, GL_RGBA, GL_FLOAT, 4, 4, true, false, false},
};

constexpr float k_half_max = 65504.f;

}  // namespace

const FormatInfo& format_info(TexFormat f) { return k_formats[int(f)]; }

Result<TexFormat> parse_format(const std::string& name) {
  for (size_t i = 0; i < std::size(k_formats); ++i)
    if (name == k_formats[i].name) return TexFormat(i);
  return invalid_argument("unknown texture format '" + name + "'");
}

float quantize(TexFormat f, float x, uint64_t* clamped) {
  const FormatInfo& fi = format_info(f);
  if (fi.is_normalized) {
    const float c = std::clamp(x, 0.f, 1.f);
    if (c != x && clamped) ++*clamped;
    return std::round(c * 255.f) / 255.f;
  }
  if (fi.is_float && fi.bytes_per_channel == 2) {
    const float c = std::clamp(x, -k_half_max, k_half_max);
    if (c != x && clamped) ++*clamped;
    return float(Imath::half(c));
  }
  return x;
}

double half_safe_scale(const std::vector<float>& values) {
  float mx = 0;
  for (float v : values)
    if (std::isfinite(v)) mx = std::max(mx, std::fabs(v));
  // Keep a factor 2 of headroom below the half maximum (bilinear filtering cannot exceed the max,
  // but sums of scaled components in the shader happen in float, so headroom costs nothing).
  double s = 1;
  while (mx / s > k_half_max / 2) s *= 2;
  return s;
}

std::vector<uint8_t> GpuTexture::level_bytes(uint32_t m) const {
  const FormatInfo& fi = format_info(format);
  const size_t n = level_values(m);
  std::vector<uint8_t> out(n * size_t(fi.bytes_per_channel));
  for (size_t i = 0; i < n; ++i) {
    uint8_t* p = out.data() + i * size_t(fi.bytes_per_channel);
    if (fi.is_integer) {
      const uint32_t v = u[m][i];
      for (int b = 0; b < fi.bytes_per_channel; ++b) p[b] = uint8_t(v >> (8 * b));
    } else if (fi.is_normalized) {
      p[0] = uint8_t(std::lround(std::clamp(f[m][i], 0.f, 1.f) * 255.f));
    } else if (fi.bytes_per_channel == 2) {
      const uint16_t h = Imath::half(f[m][i]).bits();
      p[0] = uint8_t(h), p[1] = uint8_t(h >> 8);
    } else {
      std::memcpy(p, &f[m][i], 4);
    }
  }
  return out;
}

uint64_t GpuTexture::total_bytes() const {
  uint64_t n = 0;
  for (uint32_t m = 0; m < num_levels(); ++m) n += level_values(m) * uint64_t(format_info(format).bytes_per_channel);
  return n;
}

Result<GpuTexture> make_float_texture(std::string name, TexFormat format, uint32_t width, uint32_t height, uint32_t layers,
                                      std::vector<float> level0, bool mips) {
  GpuTexture t;
  t.name = std::move(name), t.format = format, t.width = width, t.height = height, t.layers = layers;
  if (t.is_integer()) return invalid_argument("texture '" + t.name + "': integer format for float data");
  if (width == 0 || height == 0) return invalid_argument("texture '" + t.name + "': empty");
  if (level0.size() != t.level_values(0))
    return invalid_argument("texture '" + t.name + "': " + std::to_string(level0.size()) + " values for " +
                            std::to_string(t.level_values(0)) + " texels x channels");
  for (float& x : level0) {
    if (!std::isfinite(x)) return invalid_argument("texture '" + t.name + "': non-finite value");
    x = quantize(format, x, &t.clamped);
  }
  t.f.push_back(std::move(level0));
  const int ch = format_info(format).channels;
  for (uint32_t m = 1; mips && (t.level_width(m - 1) > 1 || t.level_height(m - 1) > 1); ++m) {
    const uint32_t pw = t.level_width(m - 1), ph = t.level_height(m - 1), w = t.level_width(m), h = t.level_height(m);
    const std::vector<float>& src = t.f.back();
    std::vector<float> dst(t.level_values(m));
    for (uint32_t L = 0; L < t.num_layers(); ++L)
      for (uint32_t y = 0; y < h; ++y)
        for (uint32_t x = 0; x < w; ++x)
          for (int c = 0; c < ch; ++c) {
            // Average the (up to) 2x2 parents; odd sizes fold the last row/column in.
            double s = 0;
            int n = 0;
            for (uint32_t yy = 2 * y; yy < std::min(ph, 2 * y + 2 + (h == y + 1 ? ph % 2 : 0)); ++yy)
              for (uint32_t xx = 2 * x; xx < std::min(pw, 2 * x + 2 + (w == x + 1 ? pw % 2 : 0)); ++xx)
                s += src[((size_t(L) * ph + yy) * pw + xx) * size_t(ch) + size_t(c)], ++n;
            dst[((size_t(L) * h + y) * w + x) * size_t(ch) + size_t(c)] = quantize(format, float(s / std::max(n, 1)), &t.clamped);
          }
    t.f.push_back(std::move(dst));
  }
  return t;
}

Result<GpuTexture> make_uint_texture(std::string name, TexFormat format, uint32_t width, uint32_t height, uint32_t layers,
                                     std::vector<uint32_t> level0) {
  GpuTexture t;
  t.name = std::move(name), t.format = format, t.width = width, t.height = height, t.layers = layers;
  const FormatInfo& fi = format_info(format);
  if (!fi.is_integer) return invalid_argument("texture '" + t.name + "': float format for integer data");
  if (level0.size() != t.level_values(0))
    return invalid_argument("texture '" + t.name + "': " + std::to_string(level0.size()) + " values for " +
                            std::to_string(t.level_values(0)) + " texels x channels");
  const uint64_t mx = fi.bytes_per_channel == 4 ? 0xFFFFFFFFull : (1ull << (8 * fi.bytes_per_channel)) - 1;
  for (uint32_t v : level0)
    if (v > mx) return invalid_argument("texture '" + t.name + "': index " + std::to_string(v) + " does not fit " + fi.name);
  t.u.push_back(std::move(level0));
  return t;
}

}  // namespace btfc::gpu
