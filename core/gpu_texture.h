// GPU textures as exporters build them: a format, a 2D or 2D-array shape, a mip chain, and the
// texel values exactly as the GPU will see them.
//
// Why values "as stored": the exporters' CPU emulation of each shader (tests) must read what a
// GPU reads, so a texture is quantized once, in `store()`, to its format (half rounding, 8-bit
// unorm rounding, integer range) and then holds those values. Half-float overflow is never silent:
// values beyond +-65504 are clamped to +-65504 and counted in `clamped` (the exporter reports the
// count in the manifest and on stderr); exporters avoid it by per-texture scale factors.
//
// Layout of `levels[m]` (pinned, the KTX2 / OpenGL upload order): layer-major, then rows
// (y = 0 first, the BTF image's first row), then texels, then channels:
//   value(layer, x, y, ch) = levels[m][((layer * h_m + y) * w_m + x) * channels + ch]
// with w_m = max(1, width >> m), h_m = max(1, height >> m).
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "core/status.h"

namespace btfc::gpu {

enum class TexFormat {
  r8_unorm, rg8_unorm, rgba8_unorm,        // [0,1] in 8 bits
  r8_uint, r16_uint, rg16_uint, rgba16_uint, r32_uint, rgba32_uint,  // integer indices
  r16f, rg16f, rgba16f,                    // half floats
  r32f, rg32f, rgba32f,                    // floats
};

struct FormatInfo {
  const char* name;         // "rgba16f": the manifest's spelling
  uint32_t vk_format;       // VkFormat, as KTX2 stores it
  uint32_t gl_internal;     // GL internal format enum (GL_RGBA16F = 0x881A ...)
  uint32_t gl_format;       // GL pixel format for upload (GL_RGBA, GL_RGBA_INTEGER ...)
  uint32_t gl_type;         // GL_HALF_FLOAT, GL_FLOAT, GL_UNSIGNED_BYTE ...
  int channels;             // 1, 2 or 4
  int bytes_per_channel;    // 1, 2 or 4 (KTX2 typeSize)
  bool is_float, is_integer, is_normalized;
};
const FormatInfo& format_info(TexFormat f);
Result<TexFormat> parse_format(const std::string& name);

struct GpuTexture {
  std::string name;          // file name stem and GLSL sampler name u_<name>
  TexFormat format = TexFormat::rgba16f;
  uint32_t width = 1, height = 1;
  uint32_t layers = 0;       // 0: plain 2D texture; >= 1: 2D array with that many layers
  bool linear_filter = false;  // the sampler filter the shader expects (else nearest / texelFetch)
  // Per level, layer-major values (see the file comment). Float / unorm formats use `f`,
  // integer formats use `u`.
  std::vector<std::vector<float>> f;
  std::vector<std::vector<uint32_t>> u;
  uint64_t clamped = 0;      // values clamped when stored (half overflow, unorm range)
  std::string meaning;       // one line for the manifest
  std::vector<std::string> channel_meaning;  // per channel (or per layer/channel group)
  double scale = 1, bias = 0;  // decoded value = stored * scale + bias (manifest + shader)

  uint32_t num_layers() const { return layers ? layers : 1; }
  uint32_t num_levels() const { return uint32_t(is_integer() ? u.size() : f.size()); }
  uint32_t level_width(uint32_t m) const { return width >> m ? width >> m : 1; }
  uint32_t level_height(uint32_t m) const { return height >> m ? height >> m : 1; }
  bool is_integer() const { return format_info(format).is_integer; }
  size_t level_values(uint32_t m) const {
    return size_t(level_width(m)) * level_height(m) * num_layers() * size_t(format_info(format).channels);
  }
  // Bytes of level m in the format (tightly packed, little-endian).
  std::vector<uint8_t> level_bytes(uint32_t m) const;
  uint64_t total_bytes() const;
};

// Makes a float-format (or unorm) texture from level-0 values laid out as above, quantized to
// `format`; with `mips`, appends the full mip chain (2x2 box average of the stored level above,
// so every level is the linear average of level 0, as a BTF mip level must be).
Result<GpuTexture> make_float_texture(std::string name, TexFormat format, uint32_t width, uint32_t height, uint32_t layers,
                                      std::vector<float> level0, bool mips = false);
Result<GpuTexture> make_uint_texture(std::string name, TexFormat format, uint32_t width, uint32_t height, uint32_t layers,
                                     std::vector<uint32_t> level0);

// The value the format stores for x (half rounding with clamping, unorm rounding); counts clamps.
float quantize(TexFormat f, float x, uint64_t* clamped);
// A scale s (a power of two, so scaling is exact in floats) with max|x|/s within the half range
// when the data needs it, else 1.
double half_safe_scale(const std::vector<float>& values);

}  // namespace btfc::gpu
