// KTX 2.0 container writer and reader (Khronos KTX File Format Specification 2.0).
//
// What is written (pinned; an independent parser, npm's ktx-parse, reads these files in
// tests/ktx_parse_check.mjs):
//   identifier  «KTX 20»\r\n\x1A\n
//   header      vkFormat, typeSize (bytes per channel), pixelWidth, pixelHeight, pixelDepth = 0,
//               layerCount (0 = not an array), faceCount = 1, levelCount (>= 1),
//               supercompressionScheme = 0
//   index       dfd / kvd offsets and lengths, sgd = 0
//   level index levelCount x (byteOffset, byteLength, uncompressedByteLength), level 0 first
//   DFD         one Khronos basic descriptor block: colour model RGBSDA, BT.709 primaries,
//               linear transfer, one sample per channel (float / integer / normalized flags;
//               sampleLower/Upper as the spec's format tables give them)
//   KVD         "KTXwriter" = "btfc <version>", plus the caller's pairs, sorted by key
//   levels      mip data, smallest level first in the file (the spec's order), each level's
//               offset aligned to lcm(4, texel size); within a level layer-major, rows top-down.
// Uncompressed formats only (no supercompression: the BTF data are floats and indices that
// the shader reads exactly).
#pragma once
#include <string>
#include <utility>
#include <vector>

#include "core/status.h"
#include "core/gpu_texture.h"

namespace btfc::gpu {

using KeyValues = std::vector<std::pair<std::string, std::string>>;

// Writes `t` as a KTX2 file, atomically (temporary name, then rename).
Status write_ktx2(const GpuTexture& t, const std::string& path, const KeyValues& kv = {});
// The bytes write_ktx2 writes.
std::vector<uint8_t> encode_ktx2(const GpuTexture& t, const KeyValues& kv = {});

// Reads a KTX2 file written in one of the formats of gpu_texture.h (uncompressed, one face,
// 2D or 2D array); checks every offset and length against the file size. Errors name the file.
Result<GpuTexture> read_ktx2(const std::string& path, KeyValues* kv = nullptr);
Result<GpuTexture> decode_ktx2(const std::vector<uint8_t>& bytes, const std::string& what, KeyValues* kv = nullptr);

}  // namespace btfc::gpu
