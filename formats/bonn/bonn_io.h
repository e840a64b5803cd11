// Internal to formats/bonn: bounds-checked little-endian reading and writing of Bonn .btf files,
// and the common header (signature, meta block, bidirectional sampling, size, rotations) shared
// by all four formats (formats.md 2.2, docs/FORMAT.md "Bonn .btf files").
#pragma once
#include <bit>
#include <cstdint>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "codecs/fmf/fmf.h"
#include "core/status.h"
#include "formats/bonn/bonn_btf.h"

namespace btfc::bonn {

static_assert(std::endian::native == std::endian::little, "Bonn .btf I/O assumes a little-endian host");

// Reads fields at a cursor; every read first checks the bytes left in the file, so a count is
// never trusted before it is known to fit. Reads use pread: a const ByteSource may be shared by
// threads (read_at).
class ByteSource {
 public:
  static Result<ByteSource> open(const std::string& path);
  const std::string& path() const { return m_path; }
  uint64_t pos() const { return m_pos; }
  uint64_t size() const { return m_size; }
  uint64_t remaining() const { return m_size - m_pos; }

  // corrupt_data "<path>: <field> needs N bytes at offset P, the file has R left" unless n fit.
  Status need(uint64_t n, const std::string& field) const;
  Status bytes(void* dst, uint64_t n, const std::string& field);
  Status skip(uint64_t n, const std::string& field);
  Status u8(uint8_t& v, const std::string& field) { return bytes(&v, 1, field); }
  Status u32(uint32_t& v, const std::string& field) { return bytes(&v, 4, field); }
  Status i32(int32_t& v, const std::string& field) { return bytes(&v, 4, field); }
  Status f32(float& v, const std::string& field) { return bytes(&v, 4, field); }
  // n scalars of scalar_size bytes (2 half, 4 float, 8 double) converted to float.
  Status scalars(float* dst, uint64_t n, int scalar_size, const std::string& field);
  // Thread-safe positioned read that does not move the cursor.
  Status read_at(uint64_t offset, void* dst, uint64_t n, const std::string& field) const;
  Status corrupt(const std::string& msg) const { return corrupt_data(m_path + ": " + msg); }

 private:
  std::string m_path;
  std::shared_ptr<int> m_fd;
  uint64_t m_size = 0, m_pos = 0;
};

// Buffered writer to "<path>.tmp-<pid>"; commit() renames, the destructor removes an
// uncommitted temporary.
class ByteSink {
 public:
  explicit ByteSink(std::string path) : m_path(std::move(path)) {}
  ~ByteSink();
  Status open();
  void bytes(const void* p, size_t n);
  void u8(uint8_t v) { bytes(&v, 1); }
  void u32(uint32_t v) { bytes(&v, 4); }
  void i32(int32_t v) { bytes(&v, 4); }
  void f32(float v) { bytes(&v, 4); }
  // Writes n floats as half (checking the half range) or float.
  Status scalars(const float* p, size_t n, bool half, const std::string& field);
  Status commit();

 private:
  std::string m_path, m_tmp;
  std::FILE* m_f = nullptr;
  bool m_failed = false;
};

// a * b (* c) without overflow, or false.
bool mul_ok(uint64_t a, uint64_t b, uint64_t& out);

// Signature (longest match), or "" when none matches.
std::string match_signature(const uint8_t* head, size_t n);

// The common header through the sampling: fills info.meta, info.desc (lights, views, channels).
Status read_meta(ByteSource& src, BonnMeta& meta);
Status read_sampling(ByteSource& src, BonnInfo& info);
// u32 num_rotations + 9 f32 each.
Status read_rotations(ByteSource& src, BonnInfo& info);
// u32 width, u32 height into info.desc, validated.
Status read_size(ByteSource& src, BonnInfo& info);
// Names direction sets, sets dome1 and the deviation; validates the desc.
Status finish_desc(const ByteSource& src, BonnInfo& info);

void write_meta(ByteSink& out, const BonnMeta& meta, int channels);
void write_sampling(ByteSink& out, const BtfDesc& desc);

// The whole DFMF / FMF body after the common header. With `blocks` null the bulk data is
// skipped (validated against the file size only).
struct FmfBody {
  int color_model = 0;
  float color_mean[3] = {0, 0, 0};
  float color_transform[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  bool half = true;
};
Status read_dfmf_body(ByteSource& src, BonnInfo& info, FmfBody& body, std::vector<btfc::FmfFactors>* blocks);
Status read_fmf_body(ByteSource& src, BonnInfo& info, FmfBody& body, std::vector<btfc::FmfFactors>* blocks);

// PVF and BDI: parse (and, for PVF, load) and build the model.
Result<std::unique_ptr<Model>> read_pvf(ByteSource& src, BonnInfo& info, bool load);
Result<std::unique_ptr<Model>> read_bdi(ByteSource& src, BonnInfo& info, bool load);

}  // namespace btfc::bonn
