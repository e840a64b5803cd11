// The .btfc container (docs/FORMAT.md is the byte-level spec this file implements).
//
// Every multi-byte field is written and read byte by byte in little-endian order, never by
// dumping structs, so the layout does not depend on the compiler. Only raw tensor data is
// copied straight from memory, which is why this file requires a little-endian host.
#include "core/container.h"
#include "core/quant.h"

#include <Imath/half.h>
#include <sys/stat.h>
#include <unistd.h>
#include <omp.h>
#include <zlib.h>
#if BTFC_HAVE_LIBDEFLATE
#include <libdeflate.h>
#endif

#include <algorithm>
#include <bit>
#include <cerrno>
#include <cstring>
#include <iterator>
#include <utility>
#include <vector>

#ifndef BTFC_VERSION
#define BTFC_VERSION "0.1.0"
#endif

namespace btfc {

static_assert(std::endian::native == std::endian::little,
              "tensor payloads are stored little-endian straight from memory; a big-endian port needs byte swaps");

namespace {

constexpr uint8_t k_magic[8] = {'B', 'T', 'F', 'C', '\r', '\n', 0x1a, '\n'};
constexpr uint16_t k_major = 1, k_minor = 0;
constexpr uint32_t k_header_size = 32;        // file header
constexpr uint32_t k_chunk_header_size = 32;  // keeps every payload 16-byte aligned
constexpr uint32_t k_crc_covered = 28;        // header bytes before the CRC field
constexpr uint64_t k_file_reserved_flags = 0xffffffffull;  // low half: unknown bit = error
constexpr uint32_t k_flag_critical = 1;
constexpr uint32_t k_chunk_reserved_flags = 0x0000fffe;   // bits 1..15: must be zero
constexpr uint32_t k_desc_reserved_flags = ~uint32_t(1);  // DESC flags: bit 0 = hdr
constexpr size_t k_max_string = 65536;
constexpr unsigned k_max_ndims = 8;
constexpr uint64_t k_max_meta_chunk = uint64_t(64) << 20;  // DESC/CODC/STAT are read whole at open
// Longest possible TNSR header: name string, dtype/ndims/reserved, dims, alignment padding.
constexpr size_t k_max_tensor_head = 4 + k_max_string + 4 + 8 * k_max_ndims + 15;
constexpr size_t k_io_piece = size_t(64) << 20;  // large tensors move in pieces of this size

constexpr uint32_t fourcc(const char (&s)[5]) {
  return uint32_t(uint8_t(s[0])) | uint32_t(uint8_t(s[1])) << 8 | uint32_t(uint8_t(s[2])) << 16 |
         uint32_t(uint8_t(s[3])) << 24;
}
constexpr uint32_t k_desc = fourcc("DESC"), k_codc = fourcc("CODC"), k_tnsr = fourcc("TNSR"),
                   k_stat = fourcc("STAT"), k_end = fourcc("END ");

uint64_t pad16(uint64_t n) { return (16 - n % 16) % 16; }

std::string hex(uint64_t v) {
  char buf[24];
  std::snprintf(buf, sizeof buf, "0x%llx", static_cast<unsigned long long>(v));
  return buf;
}

std::string fourcc_str(uint32_t t) {
  std::string s;
  for (int i = 0; i < 4; ++i) s += char((t >> (8 * i)) & 0xff);
  for (char c : s)
    if (c < 0x20 || c > 0x7e) {
      return hex(t);
    }
  return s;
}

// The CRC-32 of zlib and gzip. libdeflate's (PCLMULQDQ folding where the CPU has it) runs at
// 14 GB/s per core where zlib 1.2.13's runs at 6 on the Zen 5 VM (docs/benchmarks.md): it is a
// visible part of reading a multi-GB raw BTF and of the out-of-core first pass. Without
// libdeflate (a build that did not find it), zlib's, fed in pieces (it takes a 32-bit length).
uint32_t crc_piece(uint32_t crc, const uint8_t* b, uint64_t n) {
#if BTFC_HAVE_LIBDEFLATE
  return n == 0 ? crc : libdeflate_crc32(crc, b, size_t(n));  // (a null buffer would give 0)
#else
  while (n > 0) {
    const uInt k = uInt(std::min<uint64_t>(n, uint64_t(1) << 30));
    crc = uint32_t(crc32(crc, b, k));
    b += k, n -= k;
  }
  return crc;
#endif
}

// Big buffers are split over the OpenMP threads (crc32_in_pieces).
uint32_t crc_update(uint32_t crc, const void* p, uint64_t n) {
  auto* b = static_cast<const uint8_t*>(p);
  const int threads = omp_in_parallel() ? 1 : omp_get_max_threads();
  if (threads > 1 && n >= (uint64_t(8) << 20)) {
    const uint64_t per = std::min<uint64_t>((n + uint64_t(threads) - 1) / uint64_t(threads), uint64_t(1) << 30);
    return crc32_in_pieces(crc, n, per, threads, [&](uint64_t, uint64_t at, uint64_t bytes) { return crc_piece(0, b + at, bytes); });
  }
  return crc_piece(crc, b, n);
}

std::string shape_str(const std::vector<uint64_t>& shape) {
  if (shape.empty()) return "scalar";
  std::string s;
  for (size_t i = 0; i < shape.size(); ++i) {
    if (i) s += 'x';
    s += std::to_string(shape[i]);
  }
  return s;
}

// Bytes of a tensor, or false when dims x dtype overflows 64 bits.
bool tensor_bytes(const std::vector<uint64_t>& shape, DType t, uint64_t& out) {
  uint64_t n = dtype_size(t);
  for (uint64_t d : shape)
    if (__builtin_mul_overflow(n, d, &n)) return false;
  out = n;
  return true;
}

// ---- serialization -------------------------------------------------------------------------

struct Out {
  std::vector<uint8_t> b;
  void u8(uint8_t v) { b.push_back(v); }
  void u16(uint16_t v) { for (int i = 0; i < 2; ++i) b.push_back(uint8_t(v >> (8 * i))); }
  void u32(uint32_t v) { for (int i = 0; i < 4; ++i) b.push_back(uint8_t(v >> (8 * i))); }
  void u64(uint64_t v) { for (int i = 0; i < 8; ++i) b.push_back(uint8_t(v >> (8 * i))); }
  void f32(float v) { u32(std::bit_cast<uint32_t>(v)); }
  void str(const std::string& s) { u32(uint32_t(s.size())), b.insert(b.end(), s.begin(), s.end()); }
  void pad() { b.resize(b.size() + pad16(b.size()), 0); }
};

// Bounds-checked reader over a payload; errors name the file, the chunk and the field.
class Cursor {
 public:
  Cursor(const uint8_t* p, size_t n, std::string ctx) : m_p(p), m_n(n), m_ctx(std::move(ctx)) {}
  size_t pos() const { return m_pos; }
  void set_context(std::string ctx) { m_ctx = std::move(ctx); }
  size_t left() const { return m_n - m_pos; }
  Status error(const std::string& msg) const { return corrupt_data(m_ctx + ": " + msg); }
  Status need(size_t k, const char* field) const {
    if (k <= left()) return {};
    return error(std::string(field) + " needs " + std::to_string(k) + " bytes at payload offset " +
                 std::to_string(m_pos) + ", only " + std::to_string(left()) + " left");
  }
  template <class T>
  Status uint(T& v, const char* field) {
    BTFC_RETURN_IF_ERROR(need(sizeof(T), field));
    v = 0;
    for (size_t i = 0; i < sizeof(T); ++i) v = T(v | T(m_p[m_pos + i]) << (8 * i));
    m_pos += sizeof(T);
    return {};
  }
  Status f32(float& v, const char* field) {
    uint32_t u = 0;
    BTFC_RETURN_IF_ERROR(uint(u, field));
    v = std::bit_cast<float>(u);
    return {};
  }
  Status str(std::string& s, const char* field) {
    uint32_t len = 0;
    BTFC_RETURN_IF_ERROR(uint(len, field));
    if (len > k_max_string)
      return error(std::string(field) + " length " + std::to_string(len) + " exceeds " + std::to_string(k_max_string));
    BTFC_RETURN_IF_ERROR(need(len, field));
    s.assign(reinterpret_cast<const char*>(m_p + m_pos), len);
    m_pos += len;
    return {};
  }
  Status zeros(size_t k, const char* field) {
    BTFC_RETURN_IF_ERROR(need(k, field));
    for (size_t i = 0; i < k; ++i)
      if (m_p[m_pos + i]) return error(std::string(field) + " byte at payload offset " + std::to_string(m_pos + i) + " is not zero");
    m_pos += k;
    return {};
  }
  Status finish() const {
    return left() == 0 ? Status() : error(std::to_string(left()) + " unexpected bytes after the last field");
  }

 private:
  const uint8_t* m_p;
  size_t m_n, m_pos = 0;
  std::string m_ctx;
};

void put_dirs(Out& o, const DirectionSet& s) {
  o.str(s.name);
  o.u32(uint32_t(s.dirs.size()));
  for (const Vec3& d : s.dirs) o.f32(d.x), o.f32(d.y), o.f32(d.z);
}

Status get_dirs(Cursor& c, DirectionSet& s, const char* which) {
  BTFC_RETURN_IF_ERROR(c.str(s.name, which));
  uint32_t n = 0;
  BTFC_RETURN_IF_ERROR(c.uint(n, which));
  // Bound the count by the bytes present before reserving memory for it.
  if (uint64_t(n) * 12 > c.left())
    return c.error(std::string(which) + " count " + std::to_string(n) + " needs " + std::to_string(uint64_t(n) * 12) +
                   " bytes, only " + std::to_string(c.left()) + " left");
  s.dirs.resize(n);
  for (Vec3& d : s.dirs) {
    BTFC_RETURN_IF_ERROR(c.f32(d.x, which));
    BTFC_RETURN_IF_ERROR(c.f32(d.y, which));
    BTFC_RETURN_IF_ERROR(c.f32(d.z, which));
  }
  return {};
}

Status check_string(const std::string& s, const std::string& what) {
  if (s.size() > k_max_string)
    return invalid_argument(what + " is " + std::to_string(s.size()) + " bytes, over the " + std::to_string(k_max_string) + " limit");
  return {};
}

// The TNSR payload up to (and including the alignment padding before) the raw data.
std::vector<uint8_t> tensor_head(const std::string& name, DType t, const std::vector<uint64_t>& shape) {
  Out o;
  o.str(name);
  o.u8(uint8_t(t)), o.u8(uint8_t(shape.size())), o.u16(0);
  for (uint64_t d : shape) o.u64(d);
  o.pad();
  return std::move(o.b);
}

// Parses a TNSR header (the cursor covers its first bytes) and checks dims x dtype against
// the `size` of the whole payload; ti.size is the data size, the cursor ends at the data.
Status get_tensor_head(Cursor& c, const std::string& path, uint64_t size, TensorInfo& ti) {
  BTFC_RETURN_IF_ERROR(c.str(ti.name, "tensor name"));
  if (ti.name.empty()) return c.error("tensor name is empty");
  c.set_context(path + ": chunk TNSR '" + ti.name + "'");
  uint8_t dt = 0, ndims = 0;
  uint16_t res = 0;
  BTFC_RETURN_IF_ERROR(c.uint(dt, "dtype"));
  BTFC_RETURN_IF_ERROR(c.uint(ndims, "ndims"));
  BTFC_RETURN_IF_ERROR(c.uint(res, "reserved"));
  ti.dtype = DType(dt);
  if (!dtype_known(ti.dtype)) return c.error("unknown dtype " + std::to_string(dt));
  if (ndims > k_max_ndims) return c.error("ndims " + std::to_string(ndims) + " exceeds 8");
  if (res != 0) return c.error("reserved field is not zero");
  ti.shape.resize(ndims);
  for (uint64_t& d : ti.shape) BTFC_RETURN_IF_ERROR(c.uint(d, "dims"));
  BTFC_RETURN_IF_ERROR(c.zeros(pad16(c.pos()), "alignment padding"));
  ti.size = size - c.pos();
  uint64_t need;
  const std::string what = "dims " + shape_str(ti.shape) + " " + dtype_name(ti.dtype);
  if (ti.dtype == DType::zq) {  // variable size: only the element count is checked here, the rest at read
    if (ti.shape.empty() || !tensor_bytes(ti.shape, DType::u8, need)) return c.error(what + ": zq needs dims whose product fits 64 bits");
    if (ti.size < 32) return c.error(what + ": zq data of " + std::to_string(ti.size) + " bytes is shorter than its header");
    return {};
  }
  if (!tensor_bytes(ti.shape, ti.dtype, need)) return c.error(what + " overflow 64 bits");
  if (need != ti.size)
    return c.error(what + " need " + std::to_string(need) + " bytes, chunk holds " + std::to_string(ti.size));
  return {};
}

void put_desc(Out& o, const BtfDesc& d) {
  o.u32(uint32_t(d.width)), o.u32(uint32_t(d.height)), o.u32(uint32_t(d.channels));
  o.u32(d.hdr ? 1u : 0u);
  put_dirs(o, d.lights);
  put_dirs(o, d.views);
}

Status get_desc(Cursor& c, BtfDesc& d) {
  uint32_t w = 0, h = 0, ch = 0, flags = 0;
  BTFC_RETURN_IF_ERROR(c.uint(w, "width"));
  BTFC_RETURN_IF_ERROR(c.uint(h, "height"));
  BTFC_RETURN_IF_ERROR(c.uint(ch, "channels"));
  BTFC_RETURN_IF_ERROR(c.uint(flags, "flags"));
  if (w > INT32_MAX || h > INT32_MAX || ch > INT32_MAX) return c.error("width/height/channels exceed 2^31");
  if (flags & k_desc_reserved_flags) return c.error("reserved flag bits set in flags " + hex(flags));
  d.width = int(w), d.height = int(h), d.channels = int(ch), d.hdr = flags & 1;
  BTFC_RETURN_IF_ERROR(get_dirs(c, d.lights, "light set"));
  BTFC_RETURN_IF_ERROR(get_dirs(c, d.views, "view set"));
  BTFC_RETURN_IF_ERROR(c.finish());
  if (Status s = d.validate(); !s.ok()) return c.error(s.message());
  return {};
}

Status get_codec(Cursor& c, CodecInfo& ci) {
  BTFC_RETURN_IF_ERROR(c.str(ci.name, "codec name"));
  BTFC_RETURN_IF_ERROR(c.uint(ci.payload_version, "payload_version"));
  BTFC_RETURN_IF_ERROR(c.str(ci.spec, "spec"));
  BTFC_RETURN_IF_ERROR(c.str(ci.btfc_version, "btfc_version"));
  BTFC_RETURN_IF_ERROR(c.finish());
  if (ci.name.empty()) return c.error("codec name is empty");
  return {};
}

struct PlannedChunk {
  uint32_t type, flags;
  std::vector<uint8_t> head;      // whole payload of small chunks, tensor header of TNSR
  const uint8_t* data = nullptr;  // TNSR raw data (caller memory for views)
  uint64_t data_size = 0;
  const ContainerWriter::Fill* fill = nullptr;  // a streamed TNSR: data produced while writing
  uint64_t piece = 0;
  uint64_t size() const { return head.size() + data_size; }
};

struct TensorSrc {
  const std::string* name;
  DType dtype;
  const std::vector<uint64_t>* shape;
  const void* data;
  bool owned;           // a Tensor (bytes known) rather than a view of caller memory
  uint64_t owned_size;  // bytes the Tensor holds
  const ContainerWriter::Fill* fill = nullptr;
  uint64_t piece = 0;
};

Result<std::vector<PlannedChunk>> plan_chunks(const BtfDesc& desc, const CodecInfo& codec,
                                              const std::vector<TensorSrc>& tensors, const std::string& stats) {
  if (Status s = desc.validate(); !s.ok()) return s.with_context("DESC");
  if (codec.name.empty()) return invalid_argument("CODC: no codec name set");
  const std::string version = codec.btfc_version.empty() ? std::string(btfc_version()) : codec.btfc_version;
  for (const std::string* s : {&codec.name, &codec.spec, &version}) BTFC_RETURN_IF_ERROR(check_string(*s, "CODC string"));
  if (stats.size() > k_max_meta_chunk) return invalid_argument("STAT text exceeds " + std::to_string(k_max_meta_chunk) + " bytes");

  std::vector<PlannedChunk> out;
  BTFC_RETURN_IF_ERROR(check_string(desc.lights.name, "light set name"));
  BTFC_RETURN_IF_ERROR(check_string(desc.views.name, "view set name"));
  Out d;
  put_desc(d, desc);
  out.push_back({k_desc, k_flag_critical, std::move(d.b)});

  Out c;
  c.str(codec.name), c.u32(codec.payload_version), c.str(codec.spec), c.str(version);
  out.push_back({k_codc, k_flag_critical, std::move(c.b)});

  std::vector<std::string> names;
  for (const TensorSrc& t : tensors) {
    const std::string ctx = "TNSR '" + *t.name + "'";
    if (t.name->empty()) return invalid_argument("TNSR: tensor name is empty");
    BTFC_RETURN_IF_ERROR(check_string(*t.name, ctx + " name"));
    if (std::find(names.begin(), names.end(), *t.name) != names.end()) return invalid_argument(ctx + ": duplicate tensor name");
    names.push_back(*t.name);
    if (!dtype_known(t.dtype)) return invalid_argument(ctx + ": invalid dtype " + std::to_string(int(t.dtype)));
    if (t.shape->size() > k_max_ndims) return invalid_argument(ctx + ": " + std::to_string(t.shape->size()) + " dims, at most 8");
    uint64_t bytes;
    if (t.dtype == DType::zq) {  // an encoded payload: only owned tensors, header consistent with dims
      if (!t.owned) return invalid_argument(ctx + ": zq tensors are written from a Tensor, not a view or stream");
      Status s = quant::check_header(static_cast<const uint8_t*>(t.data), t.owned_size, *t.shape, ctx);
      if (!s.ok()) return invalid_argument(s.message());
      out.push_back({k_tnsr, k_flag_critical, tensor_head(*t.name, t.dtype, *t.shape), static_cast<const uint8_t*>(t.data), t.owned_size,
                     t.fill, t.piece});
      continue;
    }
    if (!tensor_bytes(*t.shape, t.dtype, bytes)) return invalid_argument(ctx + ": dims " + shape_str(*t.shape) + " overflow");
    if (t.owned && t.owned_size != bytes)
      return invalid_argument(ctx + ": dims " + shape_str(*t.shape) + " " + dtype_name(t.dtype) + " need " +
                              std::to_string(bytes) + " bytes, tensor holds " + std::to_string(t.owned_size));
    if (bytes && !t.data && !t.fill) return invalid_argument(ctx + ": null data");
    if (t.fill && (t.piece == 0 || t.piece % dtype_size(t.dtype) != 0)) return invalid_argument(ctx + ": stream piece size");
    out.push_back({k_tnsr, k_flag_critical, tensor_head(*t.name, t.dtype, *t.shape), static_cast<const uint8_t*>(t.data), bytes, t.fill,
                   t.piece});
  }
  if (!stats.empty()) out.push_back({k_stat, 0, std::vector<uint8_t>(stats.begin(), stats.end())});
  out.push_back({k_end, k_flag_critical, {}});
  return out;
}

// A chunk header; the CRC covers the header too (as PNG's covers the chunk type): a flipped type
// or size must not turn a chunk into a silently skipped one. `data_crc` continues the CRC of the
// header's covered bytes and the head over the data; a streamed chunk's is computed while writing.
std::vector<uint8_t> chunk_header_with(const PlannedChunk& ch, const std::function<uint32_t(uint32_t)>& data_crc) {
  Out h;
  h.u32(ch.type), h.u32(ch.flags), h.u64(ch.size()), h.u32(0), h.u64(0);
  uint32_t crc = crc_update(crc_update(0, h.b.data(), k_crc_covered), ch.head.data(), ch.head.size());
  h.u32(data_crc(crc));
  return std::move(h.b);
}

std::vector<uint8_t> chunk_header(const PlannedChunk& ch) {
  return chunk_header_with(ch, [&](uint32_t crc) { return crc_update(crc, ch.data, ch.data_size); });
}

std::string errno_str() { return std::strerror(errno); }

// ---- reading helpers -----------------------------------------------------------------------

Status read_at(std::FILE* f, const std::string& path, uint64_t off, void* dst, uint64_t n) {
  if (fseeko(f, off_t(off), SEEK_SET) != 0) return io_error(path + ": seek to offset " + std::to_string(off) + " failed: " + errno_str());
  auto* p = static_cast<uint8_t*>(dst);
  while (n > 0) {
    size_t k = size_t(std::min<uint64_t>(n, k_io_piece));
    if (std::fread(p, 1, k, f) != k)
      return io_error(path + ": read at offset " + std::to_string(off) + " failed: " +
                      (std::ferror(f) ? errno_str() : std::string("unexpected end of file")));
    p += k, n -= k, off += k;
  }
  return {};
}

// Reads n bytes at off into dst (or a scratch buffer when dst is null), updating crc.
Status stream_crc(std::FILE* f, const std::string& path, uint64_t off, uint64_t n, uint32_t& crc, void* dst) {
  std::vector<uint8_t> scratch(dst ? 0 : size_t(std::min<uint64_t>(n, uint64_t(1) << 20)));
  auto* out = static_cast<uint8_t*>(dst);
  while (n > 0) {
    uint64_t k = dst ? std::min<uint64_t>(n, k_io_piece) : std::min<uint64_t>(n, scratch.size());
    uint8_t* p = dst ? out : scratch.data();
    BTFC_RETURN_IF_ERROR(read_at(f, path, off, p, k));
    crc = crc_update(crc, p, k);
    if (dst) out += k;
    off += k, n -= k;
  }
  return {};
}

Status crc_check(uint32_t stored, uint32_t computed, const std::string& ctx) {
  if (stored == computed) return {};
  return corrupt_data(ctx + ": CRC mismatch (stored " + hex(stored) + ", computed " + hex(computed) + ")");
}

}  // namespace

// ---- dtypes and tensors --------------------------------------------------------------------

// Indexed by the DType code stored in TNSR (docs/FORMAT.md); code 0 is not a dtype.
static constexpr struct {
  const char* name;
  size_t size;
} k_dtypes[] = {{"invalid", 0}, {"f32", 4}, {"f16", 2}, {"u8", 1}, {"u16", 2}, {"u32", 4}, {"i32", 4}, {"f64", 8}, {"zq", 0}};

size_t dtype_size(DType t) { return size_t(t) < std::size(k_dtypes) ? k_dtypes[size_t(t)].size : 0; }
bool dtype_known(DType t) { return dtype_size(t) != 0 || t == DType::zq; }
const char* dtype_name(DType t) { return size_t(t) < std::size(k_dtypes) ? k_dtypes[size_t(t)].name : "invalid"; }

uint64_t Tensor::count() const {
  uint64_t n = 1;
  for (uint64_t d : shape) n *= d;
  return n;
}

static Tensor tensor_from(std::string name, std::vector<uint64_t> shape, DType t, const void* data) {
  Tensor r{std::move(name), t, std::move(shape), {}};
  r.bytes.resize(r.count() * dtype_size(t));
  if (!r.bytes.empty()) std::memcpy(r.bytes.data(), data, r.bytes.size());
  return r;
}

Tensor Tensor::from_f32(std::string name, std::vector<uint64_t> shape, const float* data) {
  return tensor_from(std::move(name), std::move(shape), DType::f32, data);
}

Tensor Tensor::from_u32(std::string name, std::vector<uint64_t> shape, const uint32_t* data) {
  return tensor_from(std::move(name), std::move(shape), DType::u32, data);
}

Result<std::vector<float>> Tensor::to_f32() const {
  if (dtype == DType::zq) return quant::decode(*this, "tensor '" + name + "'");
  uint64_t need;
  if (!tensor_bytes(shape, dtype, need) || need != bytes.size())
    return invalid_argument("tensor '" + name + "': dims " + shape_str(shape) + " " + dtype_name(dtype) +
                            " disagree with its " + std::to_string(bytes.size()) + " bytes");
  std::vector<float> out(count());
  const uint8_t* p = bytes.data();
  switch (dtype) {
    case DType::f32:
      if (!out.empty()) std::memcpy(out.data(), p, bytes.size());
      return out;
    case DType::f16:
      for (size_t i = 0; i < out.size(); ++i) {
        Imath::half h;
        h.setBits(uint16_t(p[2 * i] | p[2 * i + 1] << 8));
        out[i] = float(h);
      }
      return out;
    case DType::f64:
      for (size_t i = 0; i < out.size(); ++i) {
        double v;
        std::memcpy(&v, p + 8 * i, 8);
        out[i] = float(v);
      }
      return out;
    default:
      return invalid_argument("tensor '" + name + "': dtype " + dtype_name(dtype) + " is not a float type");
  }
}

// ---- writer --------------------------------------------------------------------------------

void ContainerWriter::add_tensor_view(std::string name, DType dtype, std::vector<uint64_t> shape, const void* data) {
  m_views.push_back({std::move(name), dtype, std::move(shape), data, {}, 0});
}

void ContainerWriter::add_tensor_stream(std::string name, DType dtype, std::vector<uint64_t> shape, Fill fill, uint64_t piece_bytes) {
  m_views.push_back({std::move(name), dtype, std::move(shape), nullptr, std::move(fill), piece_bytes});
}

// Owned tensors first, then views, each in insertion order (docs/FORMAT.md, chunk order).
// A template so it can take the writer's private View type by deduction.
template <class V>
static std::vector<TensorSrc> tensor_sources(const std::vector<Tensor>& tensors, const std::vector<V>& views) {
  std::vector<TensorSrc> srcs;
  for (const Tensor& t : tensors) srcs.push_back({&t.name, t.dtype, &t.shape, t.bytes.data(), true, t.bytes.size()});
  for (const V& v : views) srcs.push_back({&v.name, v.dtype, &v.shape, v.data, false, 0, v.fill ? &v.fill : nullptr, v.piece});
  return srcs;
}

uint64_t ContainerWriter::file_size() const {
  auto plan = plan_chunks(m_desc, m_codec, tensor_sources(m_tensors, m_views), m_stats);
  if (!plan.ok()) return 0;
  uint64_t n = k_header_size;
  for (const PlannedChunk& ch : plan.value()) n += k_chunk_header_size + ch.size() + pad16(ch.size());
  return n;
}

uint32_t ContainerWriter::tensor_digest() const {
  auto plan = plan_chunks(m_desc, m_codec, tensor_sources(m_tensors, m_views), std::string());
  if (!plan.ok()) return 0;
  uint32_t crc = 0;
  for (const PlannedChunk& ch : plan.value()) {
    if (ch.fill) return 0;  // its bytes exist only while writing
    const std::vector<uint8_t> hdr = chunk_header(ch);
    crc = crc_update(crc, hdr.data(), hdr.size());
    crc = crc_update(crc, ch.head.data(), ch.head.size());
    crc = crc_update(crc, static_cast<const uint8_t*>(ch.data), ch.data_size);
  }
  return crc;
}

Status ContainerWriter::write(const std::string& path) const {
  auto plan = plan_chunks(m_desc, m_codec, tensor_sources(m_tensors, m_views), m_stats);
  if (!plan.ok()) return plan.status().with_context(path);

  const std::string tmp = path + ".tmp-" + std::to_string(getpid());
  std::FILE* f = std::fopen(tmp.c_str(), "wb");
  if (!f) return io_error(path + ": cannot create temporary file '" + tmp + "': " + errno_str());
  auto put = [&](const void* p, uint64_t n) {
    auto* b = static_cast<const uint8_t*>(p);
    while (n > 0) {  // pieces: one fwrite of many GB is not portable
      size_t k = size_t(std::min<uint64_t>(n, k_io_piece));
      if (std::fwrite(b, 1, k, f) != k) return false;
      b += k, n -= k;
    }
    return true;
  };
  Out h;
  h.b.assign(std::begin(k_magic), std::end(k_magic));
  h.u16(k_major), h.u16(k_minor), h.u32(k_header_size), h.u64(0), h.u32(0);
  h.u32(crc_update(0, h.b.data(), k_crc_covered));
  bool ok = put(h.b.data(), h.b.size());
  static const uint8_t zeros[16] = {};
  Status fill_error;
  for (const PlannedChunk& ch : plan.value()) {
    if (!ok) break;
    if (!ch.fill) {
      std::vector<uint8_t> hdr = chunk_header(ch);
      ok = put(hdr.data(), hdr.size()) && put(ch.head.data(), ch.head.size()) && put(ch.data, ch.data_size) &&
           put(zeros, pad16(ch.size()));
      continue;
    }
    // Streamed: a header with a placeholder CRC, the pieces as fill() makes them (CRC running
    // over them), then the real header over the placeholder.
    const off_t at = ftello(f);
    std::vector<uint8_t> hdr = chunk_header_with(ch, [](uint32_t) { return 0u; });
    ok = at >= 0 && put(hdr.data(), hdr.size()) && put(ch.head.data(), ch.head.size());
    uint32_t dcrc = 0;
    std::vector<uint8_t> piece(size_t(std::min(ch.piece, std::max<uint64_t>(ch.data_size, 1))));
    for (uint64_t off = 0; ok && off < ch.data_size; off += piece.size()) {
      const uint64_t n = std::min<uint64_t>(piece.size(), ch.data_size - off);
      fill_error = (*ch.fill)(off, n, piece.data());
      ok = fill_error.ok() && put(piece.data(), n);
      dcrc = crc_update(dcrc, piece.data(), n);
    }
    if (!ok) break;
    hdr = chunk_header_with(ch, [&](uint32_t crc) { return uint32_t(crc32_combine(crc, dcrc, z_off_t(ch.data_size))); });
    ok = put(zeros, pad16(ch.size())) && fseeko(f, at, SEEK_SET) == 0 && put(hdr.data(), hdr.size()) && fseeko(f, 0, SEEK_END) == 0;
  }
  // Flush and sync before the rename so a crash never leaves a short file under `path`.
  ok = ok && std::fflush(f) == 0 && fsync(fileno(f)) == 0;
  std::string err = ok ? "" : errno_str();
  if (std::fclose(f) != 0 && ok) ok = false, err = errno_str();
  if (!ok) {
    std::remove(tmp.c_str());
    if (!fill_error.ok()) return fill_error.with_context(path);
    return io_error(path + ": write to '" + tmp + "' failed: " + err);
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    const std::string e = errno_str();
    std::remove(tmp.c_str());
    return io_error(path + ": cannot rename '" + tmp + "' into place: " + e);
  }
  return {};
}

// ---- reader --------------------------------------------------------------------------------

ContainerReader::ContainerReader(ContainerReader&& o) noexcept
    : m_path(std::move(o.m_path)), m_file(std::exchange(o.m_file, nullptr)), m_file_size(o.m_file_size),
      m_desc(std::move(o.m_desc)), m_codec(std::move(o.m_codec)), m_stats(std::move(o.m_stats)),
      m_tensors(std::move(o.m_tensors)), m_chunks(std::move(o.m_chunks)) {}

ContainerReader& ContainerReader::operator=(ContainerReader&& o) noexcept {
  if (this != &o) {
    if (m_file) std::fclose(m_file);
    m_path = std::move(o.m_path);
    m_file = std::exchange(o.m_file, nullptr);
    m_file_size = o.m_file_size;
    m_desc = std::move(o.m_desc);
    m_codec = std::move(o.m_codec);
    m_stats = std::move(o.m_stats);
    m_tensors = std::move(o.m_tensors);
    m_chunks = std::move(o.m_chunks);
  }
  return *this;
}

ContainerReader::~ContainerReader() {
  if (m_file) std::fclose(m_file);
}

Result<ContainerReader> ContainerReader::open(const std::string& path) {
  ContainerReader r;
  r.m_path = path;
  r.m_file = std::fopen(path.c_str(), "rb");
  if (!r.m_file) return io_error(path + ": cannot open: " + errno_str());
  struct stat st;
  if (fstat(fileno(r.m_file), &st) != 0) return io_error(path + ": cannot stat: " + errno_str());
  if (!S_ISREG(st.st_mode)) return io_error(path + ": not a regular file");
  const uint64_t fsize = r.m_file_size = uint64_t(st.st_size);
  std::FILE* f = r.m_file;

  // File header. The version is checked before the CRC: a newer major may lay the header out
  // differently, and its files deserve "unsupported" rather than "corrupt".
  if (fsize < k_header_size)
    return corrupt_data(path + ": file of " + std::to_string(fsize) + " bytes is too short for the 32-byte header");
  uint8_t hb[k_header_size];
  BTFC_RETURN_IF_ERROR(read_at(f, path, 0, hb, k_header_size));
  if (std::memcmp(hb, k_magic, 8) != 0) return corrupt_data(path + ": not a .btfc file (bad magic)");
  uint16_t major = 0, minor = 0;
  uint32_t hsize = 0, hreserved = 0, hcrc = 0;
  uint64_t hflags = 0;
  Cursor hfields(hb + 8, k_header_size - 8, path + ": header");
  BTFC_RETURN_IF_ERROR(hfields.uint(major, "major"));
  BTFC_RETURN_IF_ERROR(hfields.uint(minor, "minor"));
  if (major > k_major)
    return unsupported(path + ": container version " + std::to_string(major) + "." + std::to_string(minor) +
                       " is newer than this reader (" + std::to_string(k_major) + ".x)");
  BTFC_RETURN_IF_ERROR(hfields.uint(hsize, "header_size"));
  BTFC_RETURN_IF_ERROR(hfields.uint(hflags, "flags"));
  BTFC_RETURN_IF_ERROR(hfields.uint(hreserved, "reserved"));
  BTFC_RETURN_IF_ERROR(hfields.uint(hcrc, "crc32"));
  BTFC_RETURN_IF_ERROR(crc_check(hcrc, crc_update(0, hb, k_crc_covered), path + ": header"));
  if (major == 0) return corrupt_data(path + ": header: major version 0 is invalid");
  if (hsize != k_header_size) return corrupt_data(path + ": header: header_size " + std::to_string(hsize) + ", expected 32");
  if (hflags & k_file_reserved_flags) return corrupt_data(path + ": header: reserved flag bits set in flags " + hex(hflags));
  if (hreserved != 0) return corrupt_data(path + ": header: reserved field is not zero");

  int n_desc = 0, n_codc = 0, n_stat = 0;
  uint64_t pos = k_header_size;
  for (;;) {
    if (fsize - pos < k_chunk_header_size)
      return corrupt_data(path + ": truncated: no END chunk (" + std::to_string(fsize - pos) + " bytes left at offset " +
                          std::to_string(pos) + ", a chunk header needs 32)");
    uint8_t cb[k_chunk_header_size];
    BTFC_RETURN_IF_ERROR(read_at(f, path, pos, cb, k_chunk_header_size));
    uint32_t type = 0, flags = 0, res32 = 0, crc = 0;
    uint64_t size = 0, res64 = 0;
    Cursor cc(cb, k_chunk_header_size, path + ": chunk header at offset " + std::to_string(pos));
    BTFC_RETURN_IF_ERROR(cc.uint(type, "type"));
    BTFC_RETURN_IF_ERROR(cc.uint(flags, "flags"));
    BTFC_RETURN_IF_ERROR(cc.uint(size, "size"));
    BTFC_RETURN_IF_ERROR(cc.uint(res32, "reserved"));
    BTFC_RETURN_IF_ERROR(cc.uint(res64, "reserved"));
    BTFC_RETURN_IF_ERROR(cc.uint(crc, "crc32"));
    const std::string tname = fourcc_str(type);
    const std::string ctx = path + ": chunk " + tname + " at offset " + std::to_string(pos);
    if (res32 != 0 || res64 != 0) return corrupt_data(ctx + ": reserved header fields are not zero");
    if (flags & k_chunk_reserved_flags) return corrupt_data(ctx + ": reserved flag bits set in flags " + hex(flags));
    const uint64_t left = fsize - pos - k_chunk_header_size, payload = pos + k_chunk_header_size;
    if (size > left || pad16(size) > left - size)
      return corrupt_data(ctx + ": size " + std::to_string(size) + " (+" + std::to_string(pad16(size)) +
                          " padding) exceeds the " + std::to_string(left) + " bytes left in the file");
    const bool critical = flags & k_flag_critical;
    const bool known = type == k_desc || type == k_codc || type == k_tnsr || type == k_stat || type == k_end;
    if (!known && critical) return unsupported(ctx + ": unknown critical chunk (written by a newer btfc?)");
    if (known && critical != (type != k_stat))
      return corrupt_data(ctx + ": critical flag is " + (critical ? "set" : "clear") + ", wrong for this chunk type");
    const uint32_t hcrc0 = crc_update(0, cb, k_crc_covered);
    r.m_chunks.push_back({tname, flags, payload, size});

    if (type == k_end) {
      if (size != 0) return corrupt_data(ctx + ": END chunk has " + std::to_string(size) + " payload bytes, expected 0");
      BTFC_RETURN_IF_ERROR(crc_check(crc, hcrc0, ctx));
      if (payload != fsize)
        return corrupt_data(ctx + ": " + std::to_string(fsize - payload) + " trailing bytes after the END chunk");
      break;
    }
    if (type == k_tnsr) {
      // Parse only the tensor header; the data stays on disk until read()/read_into().
      std::vector<uint8_t> head(size_t(std::min<uint64_t>(size, k_max_tensor_head)));
      BTFC_RETURN_IF_ERROR(read_at(f, path, payload, head.data(), head.size()));
      Cursor tc(head.data(), head.size(), ctx);
      TensorInfo ti;
      BTFC_RETURN_IF_ERROR(get_tensor_head(tc, path, size, ti));
      if (r.find(ti.name)) return tc.error("duplicate tensor name");
      ti.offset = payload + tc.pos();
      ti.crc = crc;
      r.m_tensors.push_back(std::move(ti));
    } else if (known) {
      if (size > k_max_meta_chunk)
        return corrupt_data(ctx + ": size " + std::to_string(size) + " exceeds the 64 MiB limit for metadata chunks");
      std::vector<uint8_t> buf(static_cast<size_t>(size));
      BTFC_RETURN_IF_ERROR(read_at(f, path, payload, buf.data(), size));
      BTFC_RETURN_IF_ERROR(crc_check(crc, crc_update(hcrc0, buf.data(), size), ctx));
      Cursor c(buf.data(), buf.size(), ctx);
      if (type == k_desc) {
        if (n_desc++) return c.error("second DESC chunk");
        BTFC_RETURN_IF_ERROR(get_desc(c, r.m_desc));
      } else if (type == k_codc) {
        if (n_codc++) return c.error("second CODC chunk");
        BTFC_RETURN_IF_ERROR(get_codec(c, r.m_codec));
      } else {  // STAT
        if (n_stat++) return c.error("second STAT chunk");
        r.m_stats.assign(buf.begin(), buf.end());
      }
    } else {
      // Unknown optional chunk: skipped, but its CRC is still checked so a corrupted type
      // field of a known chunk cannot hide as "unknown".
      uint32_t c = hcrc0;
      BTFC_RETURN_IF_ERROR(stream_crc(f, path, payload, size, c, nullptr));
      BTFC_RETURN_IF_ERROR(crc_check(crc, c, ctx));
    }
    if (uint64_t p = pad16(size)) {
      uint8_t pad[16];
      BTFC_RETURN_IF_ERROR(read_at(f, path, payload + size, pad, p));
      for (uint64_t i = 0; i < p; ++i)
        if (pad[i]) return corrupt_data(ctx + ": chunk padding byte " + std::to_string(i) + " is not zero");
    }
    pos = payload + size + pad16(size);
  }
  if (n_desc != 1) return corrupt_data(path + ": no DESC chunk");
  if (n_codc != 1) return corrupt_data(path + ": no CODC chunk");
  return r;
}

const TensorInfo* ContainerReader::find(const std::string& name) const {
  for (const TensorInfo& t : m_tensors)
    if (t.name == name) return &t;
  return nullptr;
}

// Re-reads the chunk header and tensor header (both small) so the CRC can cover the whole
// chunk, then streams the data into dst (or through a scratch buffer when dst is null).
static Status read_tensor(std::FILE* f, const std::string& path, const std::vector<ChunkInfo>& chunks,
                          const TensorInfo& ti, void* dst) {
  const std::string ctx = path + ": chunk TNSR '" + ti.name + "'";
  const ChunkInfo* ch = nullptr;
  for (const ChunkInfo& c : chunks)
    if (c.type == "TNSR" && c.offset <= ti.offset && ti.offset <= c.offset + c.size) ch = &c;
  if (!ch) return corrupt_data(ctx + ": chunk not found");
  const uint64_t start = ch->offset - k_chunk_header_size;
  std::vector<uint8_t> prefix(size_t(ti.offset - start));
  BTFC_RETURN_IF_ERROR(read_at(f, path, start, prefix.data(), prefix.size()));
  uint32_t crc = crc_update(crc_update(0, prefix.data(), k_crc_covered), prefix.data() + k_chunk_header_size,
                            prefix.size() - k_chunk_header_size);
  BTFC_RETURN_IF_ERROR(stream_crc(f, path, ti.offset, ti.size, crc, dst));
  return crc_check(ti.crc, crc, ctx);
}

Status ContainerReader::read_into(const std::string& name, void* dst, uint64_t dst_bytes) const {
  const TensorInfo* ti = find(name);
  if (!ti) return invalid_argument(m_path + ": no tensor named '" + name + "'");
  if (dst_bytes != ti->size)
    return invalid_argument(m_path + ": chunk TNSR '" + name + "': destination holds " + std::to_string(dst_bytes) +
                            " bytes, tensor has " + std::to_string(ti->size));
  return read_tensor(m_file, m_path, m_chunks, *ti, dst);
}

Result<Tensor> ContainerReader::read(const std::string& name) const {
  const TensorInfo* ti = find(name);
  if (!ti) return invalid_argument(m_path + ": no tensor named '" + name + "'");
  Tensor t{ti->name, ti->dtype, ti->shape, {}};
  t.bytes.resize(size_t(ti->size));  // bounded: open() checked it against the file length
  BTFC_RETURN_IF_ERROR(read_into(name, t.bytes.data(), t.bytes.size()));
  return t;
}

Result<Tensor> ContainerReader::read_checked(const std::string& name, DType dtype, const std::vector<uint64_t>& shape) const {
  const TensorInfo* ti = find(name);
  if (!ti) return corrupt_data(m_path + ": missing tensor '" + name + "'");
  if (ti->dtype != dtype || (!shape.empty() && ti->shape != shape))
    return corrupt_data(m_path + ": chunk TNSR '" + name + "': is " + dtype_name(ti->dtype) + " " + shape_str(ti->shape) +
                        ", expected " + dtype_name(dtype) + " " + (shape.empty() ? "(any shape)" : shape_str(shape)));
  return read(name);
}

Result<std::vector<float>> ContainerReader::read_floats(const std::string& name, const std::vector<uint64_t>& shape) const {
  const TensorInfo* ti = find(name);
  if (!ti) return corrupt_data(m_path + ": missing tensor '" + name + "'");
  if ((ti->dtype != DType::f32 && ti->dtype != DType::f16 && ti->dtype != DType::zq) || ti->shape != shape)
    return corrupt_data(m_path + ": chunk TNSR '" + name + "': is " + dtype_name(ti->dtype) + " " + shape_str(ti->shape) +
                        ", expected f32, f16 or zq " + shape_str(shape));
  BTFC_ASSIGN_OR_RETURN(Tensor t, read(name));
  if (t.dtype == DType::zq) return quant::decode(t, m_path + ": chunk TNSR '" + name + "'");
  return t.to_f32();
}

Status ContainerReader::verify_all() const {
  for (const TensorInfo& ti : m_tensors) BTFC_RETURN_IF_ERROR(read_tensor(m_file, m_path, m_chunks, ti, nullptr));
  return {};
}

// ---- raw BTF -------------------------------------------------------------------------------

Status save_raw_btf(const Btf& btf, const std::string& path) {
  const BtfDesc& d = btf.desc();
  if (btf.size() != d.num_values()) return invalid_argument(path + ": BTF storage does not match its description");
  ContainerWriter w;
  w.set_desc(d);
  w.set_codec({"raw", 1, "raw", btfc_version()});
  w.add_tensor_view("data", DType::f32, {d.num_texels(), d.abrdf_size()}, btf.data());
  return w.write(path);
}

Status save_raw_btf_streamed(const BtfDesc& d, const std::string& path, uint64_t band_texels,
                             const std::function<Status(uint64_t t0, uint64_t n, float* dst)>& fill) {
  const uint64_t texel_bytes = d.abrdf_size() * 4;
  ContainerWriter w;
  w.set_desc(d);
  w.set_codec({"raw", 1, "raw", btfc_version()});
  w.add_tensor_stream(
      "data", DType::f32, {d.num_texels(), d.abrdf_size()},
      [&](uint64_t off, uint64_t n, void* dst) { return fill(off / texel_bytes, n / texel_bytes, static_cast<float*>(dst)); },
      std::max<uint64_t>(band_texels, 1) * texel_bytes);
  return w.write(path);
}

Result<Btf> load_raw_btf(const ContainerReader& reader) {
  const CodecInfo& c = reader.codec();
  if (c.name != "raw") return invalid_argument(reader.path() + ": codec is '" + c.name + "', not an uncompressed BTF");
  if (c.payload_version != 1)
    return unsupported(reader.path() + ": raw payload version " + std::to_string(c.payload_version) + " (this build reads 1)");
  const BtfDesc& d = reader.desc();
  const TensorInfo* ti = reader.find("data");
  const std::vector<uint64_t> want = {d.num_texels(), d.abrdf_size()};
  if (!ti) return corrupt_data(reader.path() + ": raw BTF has no tensor 'data'");
  if (ti->dtype != DType::f32 || ti->shape != want)
    return corrupt_data(reader.path() + ": chunk TNSR 'data': is " + dtype_name(ti->dtype) + " " + shape_str(ti->shape) +
                        ", DESC needs f32 " + shape_str(want));
  Result<Btf> created = Btf::create(d);  // over the memory limit: the error names the file
  if (!created.ok()) return created.status().with_context(reader.path());
  Btf b = std::move(created).value();
  BTFC_RETURN_IF_ERROR(reader.read_into("data", b.data(), uint64_t(b.size()) * sizeof(float)));
  return b;
}

const char* btfc_version() { return BTFC_VERSION; }

uint32_t crc32_update(uint32_t crc, const void* p, uint64_t n) { return crc_update(crc, p, n); }

uint32_t crc32_in_pieces(uint32_t crc, uint64_t n, uint64_t per, int threads,
                         const std::function<uint32_t(uint64_t i, uint64_t at, uint64_t bytes)>& part) {
  if (n == 0) return crc;
  per = std::max<uint64_t>(per, 1);
  const int64_t pieces = int64_t((n + per - 1) / per);
  std::vector<uint32_t> crcs(size_t(pieces), 0);
#pragma omp parallel for num_threads(int(std::clamp<int64_t>(threads, 1, pieces))) schedule(static)
  for (int64_t i = 0; i < pieces; ++i) {
    const uint64_t at = uint64_t(i) * per;
    crcs[size_t(i)] = part(uint64_t(i), at, std::min(per, n - at));
  }
  for (int64_t i = 0; i < pieces; ++i) {
    const uint64_t at = uint64_t(i) * per;
    crc = uint32_t(crc32_combine(crc, crcs[size_t(i)], z_off_t(std::min(per, n - at))));
  }
  return crc;
}

}  // namespace btfc
