// stream_lines_per_chunk (codecs/streaming.h).
#include "codecs/streaming.h"

#include <algorithm>

namespace btfc {

uint32_t stream_lines_per_chunk(const BtfDesc& desc, const StreamSizing& sizing, size_t max_bytes) {
  const uint64_t m = desc.abrdf_size();  // chunks are of the BTF matrix, whatever is factorized
  if (sizing.fixed_bytes >= max_bytes || m == 0 || desc.width <= 0) return 0;
  const uint64_t per_line = sizing.bytes_per_value * m * uint64_t(desc.width);
  uint64_t lines = (max_bytes - sizing.fixed_bytes) / per_line;
  const uint64_t cap = std::max<uint64_t>(1, (uint64_t(64) << 20) / (m * uint64_t(desc.width)));  // 64 M floats = 256 MiB
  lines = std::min({lines, cap, uint64_t(desc.height)});
  return uint32_t(lines);
}

}  // namespace btfc
