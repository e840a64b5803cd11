// Uncompressed Bonn BDI files (`!BDIF06R2!`, formats.md 2.2) written and read chunk by chunk:
// the out-of-core working file of `btfc compress --max-memory` (codecs/fmf/ooc_svd.h) and the
// streamed output of `btfc decompress -o out.btf`.
//
// Layout (the existing BDI reader, formats/bonn/bonn_raw.cpp, reads these files as BTFs):
// signature, meta block (version 4), sampling, u32 width, height, scan_lines_per_chunk,
// u8 compression = 0, u8 mask[width*height] = 1, u32 num_rotations = 0, then one chunk per
// `scan_lines_per_chunk` texel rows: u32 chunk_bytes + IEEE half values, each texel's whole
// ABRDF contiguous (row = c + nC*(l + nL*v), the order of core/btf.h), texels x fastest.
//
// Completion marker: the writer puts the placeholder k_bdi_incomplete where the signature goes
// and writes the real signature only after every chunk is on disk (fdatasync before and after).
// A file from an interrupted run therefore has no Bonn signature: BdiChunks::open and
// open_bonn_model reject it as "incomplete working file", never read it as data.
//
// Scale: half floats reach 65504. The writer stores value / scale; btfc's files record the
// scale in meta rgb_scale_factor and in the meta xml (`<btfc_work scale="..." .../>`), and
// BdiChunks multiplies it back. Foreign BDI files have scale 1 (values as stored).
//
// Contracts: errors name the file and the chunk; the writer removes its file unless finish()
// succeeded; BdiChunks::read_raw / decode / read_decoded are const and thread-safe (pread, mmap).
#pragma once
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "core/btf.h"
#include "core/chunks.h"
#include "core/status.h"

namespace btfc {

inline constexpr char k_bdi_incomplete[] = "#BTFCPART!";  // 10 bytes, as long as "!BDIF06R2!"
inline constexpr float k_half_max = 65504.0f;

class BdiWriter {
 public:
  // Creates `path` (replacing a file there) with the header and the placeholder signature.
  static Result<std::unique_ptr<BdiWriter>> create(const std::string& path, const BtfDesc& desc, uint32_t lines_per_chunk,
                                                   float scale, const std::string& xml);
  ~BdiWriter();
  BdiWriter(const BdiWriter&) = delete;
  BdiWriter& operator=(const BdiWriter&) = delete;

  uint64_t num_chunks() const { return m_chunks; }
  uint64_t texels_per_chunk() const { return m_per_chunk; }
  float scale() const { return m_scale; }
  // Largest |value| / scale seen by a failed write (> k_half_max), else 0: the caller restarts
  // with a larger scale instead of storing infinities.
  float overflow() const { return m_overflow; }

  // Texels [t0, t0 + n): whole ABRDFs, n * abrdf_size floats (core/btf.h order). Thread-safe
  // for disjoint ranges.
  Status write_texels(uint64_t t0, uint64_t n, const float* abrdfs);
  // Images [i0, i0 + k) (image i = light + nL * view) of every texel, from image-major data:
  // images[(j * texels + t) * channels + c]. Thread-safe for disjoint image ranges.
  Status write_images(uint64_t i0, uint64_t k, const float* images);
  // Flushes, writes the signature last, flushes again.
  Status finish();

 private:
  BdiWriter() = default;
  Status pwrite_all(const void* p, size_t n, uint64_t off);
  uint64_t texel_offset(uint64_t t) const;
  std::string m_path;
  BtfDesc m_desc;
  int m_fd = -1;
  uint64_t m_per_chunk = 0, m_chunks = 0, m_data0 = 0, m_size = 0;
  float m_scale = 1;
  float m_overflow = 0;
  bool m_done = false;
};

class BdiChunks {
 public:
  // A complete, uncompressed (compression 0) BDI; sparse / bzip2 BDI answer unsupported, an
  // interrupted working file corrupt_data.
  static Result<BdiChunks> open(const std::string& path);

  const std::string& path() const { return m_path; }
  const BtfDesc& desc() const { return m_desc; }
  const std::string& xml() const { return m_xml; }
  float scale() const { return m_scale; }
  uint64_t num_chunks() const { return m_chunks; }
  uint64_t chunk_first(uint64_t c) const { return c * m_per_chunk; }
  uint64_t chunk_count(uint64_t c) const;
  uint64_t chunk_bytes(uint64_t c) const { return chunk_count(c) * m_desc.abrdf_size() * 2; }
  uint64_t file_size() const { return m_size; }

  // The half values of chunk c (chunk_bytes(c) bytes).
  Status read_raw(uint64_t c, uint16_t* dst) const;
  // Half -> float times scale, chunk_count(c) * abrdf_size values; a NaN / Inf is corrupt_data
  // naming the file, the chunk and the texel.
  Status decode(uint64_t c, const uint16_t* raw, float* dst) const;
  // read_raw + decode without the raw buffer: the chunk is mapped (page cache, no copy),
  // decoded into dst and unmapped.
  Status read_decoded(uint64_t c, float* dst) const;

 private:
  std::string m_path, m_xml;
  BtfDesc m_desc;
  std::shared_ptr<int> m_fd;
  uint64_t m_per_chunk = 0, m_chunks = 0, m_data0 = 0, m_size = 0;
  float m_scale = 1;
};

// Half <-> float for n values (F16C where the CPU has it, checked at run time). to_half returns
// the largest |x|; to_floats returns false when a value is a half NaN or Inf (converted all the
// same).
float floats_to_half(const float* src, size_t n, float inv_scale, uint16_t* dst);
bool half_to_floats(const uint16_t* src, size_t n, float scale, float* dst);

// A BDI file as column chunks of the BTF matrix (rows = abrdf_size, one chunk per BDI chunk).
class BdiChunkSource final : public ChunkSource {
 public:
  explicit BdiChunkSource(const BdiChunks& f) : m_f(f) {}
  size_t rows() const override { return m_f.desc().abrdf_size(); }
  size_t num_chunks() const override { return m_f.num_chunks(); }
  size_t chunk_first(size_t c) const override { return m_f.chunk_first(c); }
  size_t chunk_count(size_t c) const override { return m_f.chunk_count(c); }
  size_t raw_bytes(size_t c) const override { return m_f.chunk_bytes(c); }
  Status read(size_t c, void* raw) const override { return m_f.read_raw(c, static_cast<uint16_t*>(raw)); }
  Status decode(size_t c, const void* raw, float* dst) const override {
    return m_f.decode(c, static_cast<const uint16_t*>(raw), dst);
  }
  // Mapped and decoded straight from the page cache: no raw half buffer.
  Status load(size_t c, void*, float* dst) const override { return m_f.read_decoded(c, dst); }
  size_t raw_buffer_bytes(size_t) const override { return 0; }

 private:
  const BdiChunks& m_f;
};

}  // namespace btfc
