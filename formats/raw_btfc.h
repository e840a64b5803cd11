// A raw (uncompressed) .btfc's data tensor, read without loading the whole BTF:
//   RawBands         texel bands in order, CRC and finite values verified (the working-file
//                    pass of formats/btf_stream.h);
//   open_raw_chunks  column chunks of the BTF matrix for the streamed SVD
//                    (codecs/fmf/ooc_svd.h), mapped from the page cache, read in place.
// Errors name the file (and the texel of a non-finite value).
#pragma once
#include <cstdint>
#include <memory>
#include <string>

#include "core/chunks.h"
#include "core/btf.h"
#include "core/status.h"

namespace btfc {

// A .btfc holding codec "raw" (desc filled when given).
bool is_raw_btfc(const std::string& path, BtfDesc* desc = nullptr);
inline bool is_raw_btfc_file(const std::string& path) { return is_raw_btfc(path, nullptr); }

// The texel-major data tensor in texel bands, strictly in order; the tensor CRC is checked when
// the last band has been read, each band's values are checked finite.
class RawBands {
 public:
  static Result<RawBands> open(const std::string& path);
  RawBands(RawBands&& o) noexcept { *this = std::move(o); }
  RawBands& operator=(RawBands&& o) noexcept;
  ~RawBands();
  const BtfDesc& desc() const { return m_desc; }
  const std::string& path() const { return m_path; }
  int fd() const { return m_fd; }
  uint64_t data_offset() const { return m_off; }  // file offset of the first value
  uint32_t crc_prefix() const { return m_crc; }   // CRC of the chunk head, before the data
  uint32_t crc_want() const { return m_crc_want; }
  // Texels [t0, t0 + n) at any position, no CRC (RawChunks keeps its own).
  Status pread_texels(uint64_t t0, uint64_t n, float* dst) const;
  // Texels [t0, t0 + n), read strictly in order (the CRC is sequential).
  Status read(uint64_t t0, uint64_t n, float* dst);

 private:
  RawBands() = default;
  Status pread_all(void* dst, uint64_t n, uint64_t off) const;
  std::string m_path;
  BtfDesc m_desc;
  int m_fd = -1;
  uint64_t m_off = 0, m_next = 0;
  uint32_t m_crc = 0, m_crc_want = 0;
};

// A raw .btfc is texel-major already: the streamed SVD reads its data tensor in place, in
// chunks of `lines_per_chunk` scan lines, with no working file. Chunks are mapped from the page
// cache (no copy, no decode; two mapped at a time: 8 bytes per value), or read into buffers
// (12 bytes per value) when the tensor is not float-aligned or the file system does not map.
// The tensor CRC is accumulated over each process's first in-order sweep and checked after the
// first pass (the processes' parts joined: finish_first_pass), each chunk's values checked
// finite when first seen.
Result<std::unique_ptr<ChunkSource>> open_raw_chunks(const std::string& path, uint32_t lines_per_chunk);

}  // namespace btfc
