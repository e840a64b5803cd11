// The .btfc container: versioned, chunked, checksummed (docs/FORMAT.md is the byte-level spec).
//
// A file is a 32-byte header then chunks {u32 fourcc, u32 flags, u64 size, 12 reserved bytes,
// u32 crc32; payload zero-padded to 16 bytes} until an "END " chunk. CRC32 is zlib's crc32 of the
// chunk header's first 28 bytes followed by the payload (so a flipped type byte is caught too).
// Chunks: DESC (the BtfDesc), CODC (codec name, codec payload version, exact spec string, btfc
// version), TNSR (one named tensor each, data 16-byte aligned), STAT (encode statistics as text,
// non-critical), END.
//
// Contracts:
//  - ContainerWriter::write writes to "<path>.tmp-<pid>" and renames on success; on failure no
//    file is left at `path` or at the temporary name.
//  - ContainerReader::open checks the magic, version, every chunk header, and every size against
//    the file length *before* allocating anything; a missing END, a truncated file, a bad CRC,
//    an unknown critical chunk or inconsistent tensor dims (dims x dtype != payload size) are
//    errors naming the file and the chunk. Small chunks (DESC, CODC, STAT) are read and verified
//    at open; tensor payloads are read (and their CRC verified) on demand, so a multi-GB raw BTF
//    streams into its destination buffer without a second copy.
//  - Not thread-safe; one reader per thread.
#pragma once
#include <cstdint>
#include <functional>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "core/btf.h"
#include "core/status.h"

namespace btfc {

// zq: quantized integers with per-column steps, zstd-coded (core/quant.h); its data size is not
// dims x an element size, so dtype_size(zq) is 0 and dtype_known() tells valid codes.
enum class DType : uint8_t { f32 = 1, f16 = 2, u8 = 3, u16 = 4, u32 = 5, i32 = 6, f64 = 7, zq = 8 };
size_t dtype_size(DType t);
bool dtype_known(DType t);
const char* dtype_name(DType t);

// A named, typed, shaped array. `bytes` holds the raw little-endian payload.
struct Tensor {
  std::string name;
  DType dtype = DType::f32;
  std::vector<uint64_t> shape;
  std::vector<uint8_t> bytes;

  uint64_t count() const;  // product of shape
  static Tensor from_f32(std::string name, std::vector<uint64_t> shape, const float* data);
  static Tensor from_u32(std::string name, std::vector<uint64_t> shape, const uint32_t* data);
  // Converts f32 / f16 / f64 payloads to float, and decodes zq ones; errors for integer dtypes.
  Result<std::vector<float>> to_f32() const;
};

struct CodecInfo {
  std::string name;           // "fmf"; "raw" for an uncompressed BTF
  uint32_t payload_version = 0;
  std::string spec;           // exact canonical spec string
  std::string btfc_version;   // of the writer
};

class ContainerWriter {
 public:
  void set_desc(const BtfDesc& desc) { m_desc = desc; }
  void set_codec(const CodecInfo& info) { m_codec = info; }
  void add_tensor(Tensor t) { m_tensors.push_back(std::move(t)); }
  // A float tensor written straight from caller memory (no copy), e.g. a raw BTF's data.
  // The pointer must stay valid until write() returns.
  void add_tensor_view(std::string name, DType dtype, std::vector<uint64_t> shape, const void* data);
  // A tensor produced while writing, for payloads larger than memory: write() calls
  // fill(offset, n, dst) for consecutive byte ranges of at most piece_bytes (offset and n
  // multiples of the dtype size), writes each, and puts the chunk's CRC into its header last.
  // tensor_digest() is 0 for a writer holding one.
  using Fill = std::function<Status(uint64_t offset, uint64_t n, void* dst)>;
  void add_tensor_stream(std::string name, DType dtype, std::vector<uint64_t> shape, Fill fill, uint64_t piece_bytes);
  void set_stats(std::string text) { m_stats = std::move(text); }
  Status write(const std::string& path) const;
  // Total bytes write() would produce.
  uint64_t file_size() const;
  // CRC-32 over every tensor chunk (header + payload) write() would produce: the model's bytes
  // without the statistics (which hold timings), for determinism checks.
  uint32_t tensor_digest() const;

 private:
  struct View {
    std::string name;
    DType dtype;
    std::vector<uint64_t> shape;
    const void* data;
    Fill fill;  // set: a streamed tensor (data is a placeholder)
    uint64_t piece = 0;
  };
  BtfDesc m_desc;
  CodecInfo m_codec;
  std::vector<Tensor> m_tensors;
  std::vector<View> m_views;
  std::string m_stats;
};

struct TensorInfo {
  std::string name;
  DType dtype;
  std::vector<uint64_t> shape;
  uint64_t offset;   // payload offset in the file
  uint64_t size;     // payload bytes
  uint32_t crc;
};

struct ChunkInfo {
  std::string type;  // fourcc
  uint32_t flags;
  uint64_t offset, size;
};

class ContainerReader {
 public:
  static Result<ContainerReader> open(const std::string& path);
  ContainerReader(ContainerReader&&) noexcept;
  ContainerReader& operator=(ContainerReader&&) noexcept;
  ~ContainerReader();

  const std::string& path() const { return m_path; }
  const BtfDesc& desc() const { return m_desc; }
  const CodecInfo& codec() const { return m_codec; }
  const std::string& stats() const { return m_stats; }
  const std::vector<TensorInfo>& tensors() const { return m_tensors; }
  const std::vector<ChunkInfo>& chunks() const { return m_chunks; }
  uint64_t file_size() const { return m_file_size; }
  const TensorInfo* find(const std::string& name) const;

  // Reads one tensor, verifying its CRC. Errors name the file and the tensor.
  Result<Tensor> read(const std::string& name) const;
  // Reads a tensor and checks its dtype and shape (an empty `shape` accepts any shape).
  Result<Tensor> read_checked(const std::string& name, DType dtype, const std::vector<uint64_t>& shape) const;
  // Reads a float tensor of the given shape stored as f32, f16 or zq, as floats (checks shape and
  // dtype; a zq tensor is decoded, with its errors naming the file and the tensor).
  Result<std::vector<float>> read_floats(const std::string& name, const std::vector<uint64_t>& shape) const;
  // Streams a tensor's payload into dst (dst_bytes must equal its size), verifying the CRC.
  Status read_into(const std::string& name, void* dst, uint64_t dst_bytes) const;
  // Reads every tensor payload and checks its CRC (btfc info --verify).
  Status verify_all() const;

 private:
  ContainerReader() = default;
  std::string m_path;
  std::FILE* m_file = nullptr;
  uint64_t m_file_size = 0;
  BtfDesc m_desc;
  CodecInfo m_codec;
  std::string m_stats;
  std::vector<TensorInfo> m_tensors;
  std::vector<ChunkInfo> m_chunks;
};

// Uncompressed BTFs use the same container with codec name "raw" and one f32 tensor "data"
// of shape [num_texels, abrdf_size] in the layout of core/btf.h.
Status save_raw_btf(const Btf& btf, const std::string& path);
// The same for a BTF that is never whole in memory: fill(t0, n, dst) decodes texels
// [t0, t0 + n) (n * abrdf_size floats) for bands of at most band_texels, in order.
Status save_raw_btf_streamed(const BtfDesc& desc, const std::string& path, uint64_t band_texels,
                             const std::function<Status(uint64_t t0, uint64_t n, float* dst)>& fill);
Result<Btf> load_raw_btf(const ContainerReader& reader);

// Version string of this build, stored in CODC.
const char* btfc_version();

// zlib's crc32 of n bytes continuing `crc`, for any n; buffers of 8 MiB and more are split over
// the OpenMP threads (crc32_in_pieces).
uint32_t crc32_update(uint32_t crc, const void* p, uint64_t n);

// `crc` continued over n bytes cut into contiguous pieces of `per` bytes (the last one shorter):
// part(i, at, bytes) gives piece i's own CRC (from 0) of bytes [at, at + bytes), computed on up
// to `threads` OpenMP threads, and the pieces are joined in order with crc32_combine. The one
// way btfc splits a CRC over threads (crc32_update; a raw .btfc's checks, which test the values
// of each piece while it is in cache).
uint32_t crc32_in_pieces(uint32_t crc, uint64_t n, uint64_t per, int threads,
                         const std::function<uint32_t(uint64_t i, uint64_t at, uint64_t bytes)>& part);

}  // namespace btfc
