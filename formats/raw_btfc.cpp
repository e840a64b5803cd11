// Raw .btfc data read in bands or mapped chunks; see raw_btfc.h.
#include "formats/raw_btfc.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cstring>
#include <mutex>
#include <vector>

#include "core/container.h"

namespace btfc {
namespace {

Status non_finite_error(const std::string& path, const BtfDesc& d, uint64_t texel) {
  return corrupt_data(path + ": non-finite value at texel (" + std::to_string(texel % uint64_t(d.width)) + ", " +
                      std::to_string(texel / uint64_t(d.width)) + ")");
}

// crc32 of v[0, n) continuing `crc`, and (when bad is given) the index of the first non-finite
// value in *bad (n when none), in 256 KiB blocks: each block is tested while in cache and then
// CRC-ed, one trip through memory instead of two. On one thread unless the caller's scope allows
// more (CheckThreads, core/chunks.h): it runs on the chunk-reader thread while the GEMMs hold
// both cores, where an OpenMP team measured no faster on the 5 GB benchmark and 2.4x slower when
// the main thread's BLAS threads spun alongside it. With T threads, T contiguous pieces
// (crc32_in_pieces, core/container.h), the first bad index the smallest piece's.
uint32_t crc_and_check_serial(uint32_t crc, const float* v, size_t n, size_t* bad) {
  const size_t block = size_t(1) << 16;
  if (bad) *bad = n;
  for (size_t i0 = 0; i0 < n; i0 += block) {
    const size_t k = std::min(block, n - i0);
    if (bad && *bad == n) {
      const size_t i = find_non_finite(v + i0, k);
      if (i < k) *bad = i0 + i;
    }
    crc = crc32_update(crc, v + i0, k * 4);
  }
  return crc;
}

uint32_t crc_and_check(uint32_t crc, const float* v, size_t n, size_t* bad) {
  const size_t threads = size_t(CheckThreads::get()), min_piece = size_t(1) << 20;  // floats
  if (threads < 2 || n < 2 * min_piece) return crc_and_check_serial(crc, v, n, bad);
  const size_t pieces = std::min(threads, n / min_piece), per = (n + pieces - 1) / pieces;
  std::vector<size_t> first(pieces, n);
  crc = crc32_in_pieces(crc, uint64_t(n) * 4, uint64_t(per) * 4, int(pieces), [&](uint64_t i, uint64_t at, uint64_t bytes) {
    const size_t a = size_t(at / 4), k = size_t(bytes / 4);
    size_t b = k;
    const uint32_t c = crc_and_check_serial(0, v + a, k, bad ? &b : nullptr);
    first[size_t(i)] = b < k ? a + b : n;
    return c;
  });
  if (bad) *bad = *std::min_element(first.begin(), first.end());
  return crc;
}

// A raw .btfc read in place as column chunks of B for the streamed SVD: its data tensor is
// texel-major already (each texel's ABRDF contiguous), so no working file is needed, and the
// chunks are mapped, not copied: the GEMMs read the page cache directly (no pread copy, no
// decode), which is what keeps out-of-core passes near in-core speed. The tensor CRC is
// accumulated over the first in-order sweep of each process's chunks (pass 0) and checked
// after that pass, the processes' parts joined (finish_first_pass): so MPI ranks can each map
// only their own chunks. Each chunk's values are checked finite the first time it is seen.
// (A file truncated by another process while mapped would raise SIGBUS; its size is checked
// at open.) A tensor at an offset not aligned for floats falls back to pread + copy.
class RawChunks final : public ChunkSource {
 public:
  RawChunks(RawBands b, uint64_t per_chunk) : m_b(std::move(b)), m_per(per_chunk) {
    const uint64_t n = m_b.desc().num_texels();
    m_chunks = (n + m_per - 1) / m_per;
    m_checked.assign(m_chunks, 0);
    m_page = uint64_t(::sysconf(_SC_PAGESIZE));
    // Mapped when the floats are aligned and the file system maps (some FUSE ones do not).
    if (m_b.data_offset() % alignof(float) == 0) {
      void* p = ::mmap(nullptr, size_t(m_page), PROT_READ, MAP_SHARED, m_b.fd(), 0);
      if (p != MAP_FAILED) m_mappable = true, ::munmap(p, size_t(m_page));
    }
  }
  size_t rows() const override { return m_b.desc().abrdf_size(); }
  size_t num_chunks() const override { return m_chunks; }
  size_t chunk_first(size_t c) const override { return c * m_per; }
  size_t chunk_count(size_t c) const override { return std::min<uint64_t>(m_per, m_b.desc().num_texels() - c * m_per); }
  size_t raw_bytes(size_t c) const override { return chunk_count(c) * rows() * 4; }
  Status read(size_t c, void* raw) const override {
    BTFC_RETURN_IF_ERROR(m_b.pread_texels(chunk_first(c), chunk_count(c), static_cast<float*>(raw)));
    return verify(c, static_cast<const float*>(raw));
  }
  Status decode(size_t c, const void* raw, float* dst) const override {
    std::memcpy(dst, raw, raw_bytes(c));
    return {};
  }
  // The pread fallback reads straight into the caller's float block: the file's bytes are the
  // block's already, so the raw buffer and the second copy read() + decode() would make are
  // saved (a chunk's worth of memory, and a copy of the whole file per pass).
  Status load(size_t c, void*, float* dst) const override {
    BTFC_RETURN_IF_ERROR(m_b.pread_texels(chunk_first(c), chunk_count(c), dst));
    return verify(c, dst);
  }
  size_t raw_buffer_bytes(size_t) const override { return 0; }
  bool mappable() const override { return m_mappable; }
  Result<const float*> map(size_t c) const override {
    const uint64_t off = chunk_offset(c), base = off / m_page * m_page;
    void* p = ::mmap(nullptr, size_t(raw_bytes(c) + (off - base)), PROT_READ, MAP_SHARED | MAP_POPULATE, m_b.fd(), off_t(base));
    if (p == MAP_FAILED) return io_error(m_b.path() + ": cannot map texel chunk " + std::to_string(c) + " (" + std::strerror(errno) + ")");
    const float* f = reinterpret_cast<const float*>(static_cast<const uint8_t*>(p) + (off - base));
    Status s = verify(c, f);
    if (!s.ok()) {
      unmap(c, f);
      return s;
    }
    return f;
  }
  void unmap(size_t c, const float* f) const override {
    const uint64_t off = chunk_offset(c), base = off / m_page * m_page;
    ::munmap(const_cast<uint8_t*>(reinterpret_cast<const uint8_t*>(f)) - (off - base), size_t(raw_bytes(c) + (off - base)));
  }

 private:
  uint64_t chunk_offset(size_t c) const { return m_b.data_offset() + uint64_t(chunk_first(c)) * rows() * 4; }
  // First sight of chunk c: values finite. The first chunk this process maps starts its CRC
  // sweep (from the tensor head's CRC when it is chunk 0, else from 0); each next chunk in order
  // extends it. Both tests share one trip through memory (crc_and_check).
  Status verify(size_t c, const float* v) const {
    std::lock_guard<std::mutex> lock(m_mutex);
    if (m_start == k_none) m_start = m_next = c, m_crc = c == 0 ? m_b.crc_prefix() : 0;
    const size_t n = chunk_count(c) * rows();
    const bool crc = c == m_next;
    size_t bad = n;
    if (crc)
      m_crc = crc_and_check(m_crc, v, n, m_checked[c] ? nullptr : &bad);
    else if (!m_checked[c])
      bad = find_non_finite(v, n);
    if (bad < n) return non_finite_error(m_b.path(), m_b.desc(), chunk_first(c) + bad / rows());
    m_checked[c] = 1;
    if (crc) ++m_next;
    return {};
  }

 public:
  // The processes' sweeps [start, next) with their CRCs, summed into one table (each process
  // fills its own row), are joined in chunk order with crc32_combine and compared with the
  // tensor's CRC, on every process alike. Sweeps that do not tile every chunk (a caller that
  // streamed only some chunks) cannot be checked and are not.
  Status finish_first_pass(Collective& coll) const override {
    const size_t P = size_t(coll.size()), r = size_t(coll.rank());
    std::vector<double> t(3 * P, 0.0);
    {
      std::lock_guard<std::mutex> lock(m_mutex);
      if (m_start != k_none && m_next > m_start) t[3 * r] = double(m_start) + 1, t[3 * r + 1] = double(m_next), t[3 * r + 2] = double(m_crc);
    }
    BTFC_RETURN_IF_ERROR(coll.allreduce_sum(t.data(), t.size()));
    std::vector<std::array<uint64_t, 3>> parts;  // start, end, crc (all exact in a double)
    for (size_t i = 0; i < P; ++i)
      if (t[3 * i] > 0) parts.push_back({uint64_t(t[3 * i]) - 1, uint64_t(t[3 * i + 1]), uint64_t(t[3 * i + 2])});
    std::sort(parts.begin(), parts.end());
    uint64_t expect = 0;
    uint32_t crc = 0;
    for (const auto& [a, b, c] : parts) {
      if (a != expect) return {};
      const uint64_t bytes = (uint64_t(chunk_first(b - 1)) + chunk_count(b - 1) - chunk_first(a)) * rows() * 4;
      crc = a == 0 ? uint32_t(c) : uint32_t(crc32_combine(crc, uint32_t(c), z_off_t(bytes)));
      expect = b;
    }
    if (expect != m_chunks) return {};
    if (crc != m_b.crc_want()) return corrupt_data(m_b.path() + ": chunk TNSR 'data': CRC mismatch (the file is corrupt)");
    return {};
  }

 private:
  static constexpr uint64_t k_none = ~uint64_t(0);
  RawBands m_b;
  uint64_t m_per = 1, m_chunks = 0, m_page = 4096;
  bool m_mappable = false;
  mutable std::mutex m_mutex;
  mutable uint64_t m_start = k_none, m_next = 0;
  mutable uint32_t m_crc = 0;
  mutable std::vector<uint8_t> m_checked;
};

}  // namespace

bool is_raw_btfc(const std::string& path, BtfDesc* desc) {
  auto rd = ContainerReader::open(path);
  if (!rd.ok() || rd->codec().name != "raw") return false;
  if (desc) *desc = rd->desc();
  return true;
}

Result<RawBands> RawBands::open(const std::string& path) {
  BTFC_ASSIGN_OR_RETURN(ContainerReader rd, ContainerReader::open(path));
  const TensorInfo* ti = rd.find("data");
  const BtfDesc& d = rd.desc();
  if (!ti || ti->dtype != DType::f32 || ti->shape != std::vector<uint64_t>{d.num_texels(), d.abrdf_size()})
    return corrupt_data(path + ": raw BTF without an f32 'data' tensor of [texels, abrdf_size]");
  RawBands r;
  r.m_path = path;
  r.m_desc = d;
  r.m_off = ti->offset;
  r.m_crc_want = ti->crc;
  const ChunkInfo* ch = nullptr;
  for (const ChunkInfo& c : rd.chunks())
    if (c.type == "TNSR" && c.offset <= ti->offset && ti->offset <= c.offset + c.size) ch = &c;
  if (!ch) return corrupt_data(path + ": chunk TNSR 'data' not found");
  r.m_fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (r.m_fd < 0) return io_error(path + ": cannot open (" + std::strerror(errno) + ")");
  // The CRC covers the chunk header's first 28 bytes, then the payload (tensor head + data).
  const uint64_t start = ch->offset - 32;
  std::vector<uint8_t> prefix(size_t(ti->offset - start));
  BTFC_RETURN_IF_ERROR(r.pread_all(prefix.data(), prefix.size(), start));
  r.m_crc = uint32_t(crc32(0, prefix.data(), 28));
  r.m_crc = uint32_t(crc32(r.m_crc, prefix.data() + 32, uInt(prefix.size() - 32)));
  return r;
}

RawBands& RawBands::operator=(RawBands&& o) noexcept {
  std::swap(m_fd, o.m_fd);
  m_path = o.m_path, m_desc = o.m_desc, m_off = o.m_off, m_crc = o.m_crc, m_crc_want = o.m_crc_want, m_next = o.m_next;
  return *this;
}

RawBands::~RawBands() {
  if (m_fd >= 0) ::close(m_fd);
}

Status RawBands::pread_texels(uint64_t t0, uint64_t n, float* dst) const {
  return pread_all(dst, n * m_desc.abrdf_size() * 4, m_off + t0 * m_desc.abrdf_size() * 4);
}

Status RawBands::read(uint64_t t0, uint64_t n, float* dst) {
  if (t0 != m_next) return invalid_argument(m_path + ": raw bands must be read in order");
  const uint64_t bytes = n * m_desc.abrdf_size() * 4;
  BTFC_RETURN_IF_ERROR(pread_all(dst, bytes, m_off + t0 * m_desc.abrdf_size() * 4));
  m_crc = crc32_update(m_crc, dst, bytes);
  m_next = t0 + n;
  if (m_next == m_desc.num_texels() && m_crc != m_crc_want)
    return corrupt_data(m_path + ": chunk TNSR 'data': CRC mismatch (the file is corrupt)");
  const size_t values = size_t(n * m_desc.abrdf_size()), i = find_non_finite(dst, values);
  return i < values ? non_finite_error(m_path, m_desc, t0 + i / m_desc.abrdf_size()) : Status{};
}

Status RawBands::pread_all(void* dst, uint64_t n, uint64_t off) const {
  uint8_t* p = static_cast<uint8_t*>(dst);
  while (n > 0) {
    const ssize_t r = ::pread(m_fd, p, size_t(std::min<uint64_t>(n, uint64_t(1) << 30)), off_t(off));
    if (r < 0 && errno == EINTR) continue;
    if (r <= 0) return io_error(m_path + ": read failed at offset " + std::to_string(off));
    p += r, off += uint64_t(r), n -= uint64_t(r);
  }
  return {};
}

Result<std::unique_ptr<ChunkSource>> open_raw_chunks(const std::string& path, uint32_t lines_per_chunk) {
  if (!is_raw_btfc(path, nullptr)) return invalid_argument(path + ": not a raw (uncompressed) .btfc");
  BTFC_ASSIGN_OR_RETURN(RawBands b, RawBands::open(path));
  const uint64_t per = uint64_t(std::max<uint32_t>(lines_per_chunk, 1)) * uint64_t(b.desc().width);
  return std::unique_ptr<ChunkSource>(std::make_unique<RawChunks>(std::move(b), per));
}


}  // namespace btfc
