// Bounded-memory BTF input / output; see btf_stream.h.
#include "formats/btf_stream.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>
#include <omp.h>
#include <zlib.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <future>
#include <mutex>

#include "codecs/fmf/ooc_fmf.h"
#include "core/container.h"
#include "formats/bonn/bdi_work.h"
#include "formats/bonn/bonn_btf.h"
#include "formats/btf_io.h"
#include "formats/image_set.h"

namespace btfc {
namespace {

namespace fs = std::filesystem;

bool is_raw_btfc(const std::string& path, BtfDesc* desc) {
  auto rd = ContainerReader::open(path);
  if (!rd.ok() || rd->codec().name != "raw") return false;
  if (desc) *desc = rd->desc();
  return true;
}

// "source=... bytes=... mtime=...": identifies the input a working file was made from.
std::string fingerprint(const std::string& input) {
  std::error_code ec;
  const std::string abs = fs::absolute(input, ec).lexically_normal().string();
  uint64_t bytes = 0, count = 0;
  int64_t mtime = 0;
  auto add = [&](const fs::path& p) {
    struct stat st {};
    if (::stat(p.c_str(), &st) == 0) {
      bytes += uint64_t(st.st_size), ++count;
      mtime = std::max<int64_t>(mtime, int64_t(st.st_mtim.tv_sec) * 1000000000 + st.st_mtim.tv_nsec);
    }
  };
  if (fs::is_directory(input, ec)) {
    for (auto it = fs::recursive_directory_iterator(input, ec); !ec && it != fs::recursive_directory_iterator(); it.increment(ec))
      if (it->is_regular_file(ec)) add(it->path());
  } else {
    add(input);
  }
  std::string q;  // xml attribute value: escape what would end it
  for (char c : abs) q += c == '"' ? std::string("&quot;") : c == '&' ? std::string("&amp;") : c == '<' ? std::string("&lt;") : std::string(1, c);
  return "source=\"" + q + "\" source_bytes=\"" + std::to_string(bytes) + "\" source_files=\"" + std::to_string(count) +
         "\" source_mtime=\"" + std::to_string(mtime) + "\"";
}

Status non_finite_error(const std::string& path, const BtfDesc& d, uint64_t texel) {
  return corrupt_data(path + ": non-finite value at texel (" + std::to_string(texel % uint64_t(d.width)) + ", " +
                      std::to_string(texel / uint64_t(d.width)) + ")");
}

// Streams a raw .btfc's data tensor in texel bands, verifying the tensor's CRC at the end.
class RawBands {
 public:
  static Result<RawBands> open(const std::string& path) {
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
  RawBands(RawBands&& o) noexcept { *this = std::move(o); }
  RawBands& operator=(RawBands&& o) noexcept {
    std::swap(m_fd, o.m_fd);
    m_path = o.m_path, m_desc = o.m_desc, m_off = o.m_off, m_crc = o.m_crc, m_crc_want = o.m_crc_want, m_next = o.m_next;
    return *this;
  }
  ~RawBands() {
    if (m_fd >= 0) ::close(m_fd);
  }
  const BtfDesc& desc() const { return m_desc; }
  const std::string& path() const { return m_path; }
  int fd() const { return m_fd; }
  uint64_t data_offset() const { return m_off; }  // file offset of the first value
  uint32_t crc_prefix() const { return m_crc; }  // CRC of the chunk head, before the data
  uint32_t crc_want() const { return m_crc_want; }
  // Texels [t0, t0 + n) at any position, no CRC (RawChunks keeps its own).
  Status pread_texels(uint64_t t0, uint64_t n, float* dst) const {
    return pread_all(dst, n * m_desc.abrdf_size() * 4, m_off + t0 * m_desc.abrdf_size() * 4);
  }
  // Texels [t0, t0 + n), read strictly in order (the CRC is sequential).
  Status read(uint64_t t0, uint64_t n, float* dst) {
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

 private:
  RawBands() = default;
  Status pread_all(void* dst, uint64_t n, uint64_t off) const {
    uint8_t* p = static_cast<uint8_t*>(dst);
    while (n > 0) {
      const ssize_t r = ::pread(m_fd, p, size_t(std::min<uint64_t>(n, uint64_t(1) << 30)), off_t(off));
      if (r < 0 && errno == EINTR) continue;
      if (r <= 0) return io_error(m_path + ": read failed at offset " + std::to_string(off));
      p += r, off += uint64_t(r), n -= uint64_t(r);
    }
    return {};
  }
  std::string m_path;
  BtfDesc m_desc;
  int m_fd = -1;
  uint64_t m_off = 0, m_next = 0;
  uint32_t m_crc = 0, m_crc_want = 0;
};

// crc32 of v[0, n) continuing `crc`, and (when bad is given) the index of the first non-finite
// value in *bad (n when none). Each thread takes a contiguous piece and walks it in 256 KiB
// blocks, testing each block while it is in cache and then CRC-ing it: one trip through memory
// instead of two, which is most of the cost of the first pass over a mapped multi-GB tensor.
uint32_t crc_and_check(uint32_t crc, const float* v, size_t n, size_t* bad) {
  const int threads = std::max(1, omp_get_max_threads());
  const size_t piece = (n + size_t(threads) - 1) / size_t(threads), block = size_t(1) << 16;
  std::vector<uint32_t> part(size_t(threads), 0);
  std::vector<size_t> first(size_t(threads), n);
#pragma omp parallel for schedule(static, 1) num_threads(threads)
  for (int t = 0; t < threads; ++t) {
    const size_t a = std::min(n, size_t(t) * piece), b = std::min(n, a + piece);
    uint32_t c = 0;
    for (size_t i0 = a; i0 < b; i0 += block) {
      const size_t k = std::min(block, b - i0);
      if (bad && first[size_t(t)] == n) {
        const size_t i = find_non_finite(v + i0, k);
        if (i < k) first[size_t(t)] = i0 + i;
      }
      c = crc32_update(c, v + i0, k * 4);
    }
    part[size_t(t)] = c;
  }
  for (int t = 0; t < threads; ++t) {
    const size_t a = std::min(n, size_t(t) * piece), b = std::min(n, a + piece);
    if (b > a) crc = uint32_t(crc32_combine(crc, part[size_t(t)], z_off_t((b - a) * 4)));
  }
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
class RawChunks final : public fmf::ChunkSource {
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
  Status finish_first_pass(fmf::Collective& coll) const override {
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

// Rows of texels per band for `bytes_per_value` bytes of buffer per value within max_bytes.
uint64_t band_lines(const BtfDesc& d, uint64_t bytes_per_value, size_t max_bytes) {
  const uint64_t per_line = bytes_per_value * d.abrdf_size() * uint64_t(d.width);
  return std::clamp<uint64_t>(max_bytes / per_line, 1, uint64_t(d.height));
}

// One attempt at filling `w` from the input; an overflow (w.overflow() > 0) asks for a retry.
Status fill(const std::string& input, BdiWriter& w, const BtfDesc& d, size_t max_bytes, Progress* progress) {
  std::error_code ec;
  const uint64_t texels = d.num_texels(), width = uint64_t(d.width);
  if (fs::is_directory(input, ec)) {
    BTFC_ASSIGN_OR_RETURN(ImageSetPlan plan, plan_image_set(input));
    const uint64_t img_bytes = texels * uint64_t(d.channels) * 4;
    // Decoded images (float) + their half segments; OIIO's own per-image buffers come on top.
    const uint64_t k = std::clamp<uint64_t>(max_bytes / 2 / img_bytes, 1, d.num_images());
    std::vector<float> buf(k * texels * uint64_t(d.channels));
    if (progress) progress->start("working file (image groups)", (d.num_images() + k - 1) / k);
    for (uint64_t i0 = 0; i0 < d.num_images(); i0 += k) {
      const uint64_t n = std::min(k, d.num_images() - i0);
      BTFC_RETURN_IF_ERROR(read_images(plan, i0, i0 + n, buf.data()));
      BTFC_RETURN_IF_ERROR(w.write_images(i0, n, buf.data()));
      if (progress) progress->advance();
    }
    if (progress) progress->finish();
    return {};
  }
  if (is_raw_btfc(input, nullptr)) {
    BTFC_ASSIGN_OR_RETURN(RawBands rb, RawBands::open(input));
    // Two float bands (the next one is read on a helper thread while this one is converted and
    // written) and the half copy of one band: 10 B/value.
    const uint64_t lines = band_lines(d, 10, max_bytes);
    std::vector<float> buf[2];
    buf[0].resize(lines * width * d.abrdf_size());
    buf[1].resize(buf[0].size());
    const uint64_t bands = (uint64_t(d.height) + lines - 1) / lines;
    auto count = [&](uint64_t b) { return std::min(lines, uint64_t(d.height) - b * lines) * width; };
    auto read = [&](uint64_t b) { return std::async(std::launch::async, [&, b] { return rb.read(b * lines * width, count(b), buf[b % 2].data()); }); };
    if (progress) progress->start("working file (raw texel bands)", bands);
    std::future<Status> next = read(0);
    for (uint64_t b = 0; b < bands; ++b) {
      Status s = next.get();
      if (s.ok() && b + 1 < bands) next = read(b + 1);
      if (s.ok()) s = w.write_texels(b * lines * width, count(b), buf[b % 2].data());
      if (!s.ok()) {
        if (next.valid()) (void)next.get();
        return s;
      }
      if (progress) progress->advance();
    }
    if (progress) progress->finish();
    return {};
  }
  BTFC_ASSIGN_OR_RETURN(auto model, open_model(input));
  const uint64_t lines = band_lines(d, 6, max_bytes);
  Btf band;
  if (progress) progress->start("working file (decoded texel bands)", (uint64_t(d.height) + lines - 1) / lines);
  for (uint64_t y = 0; y < uint64_t(d.height); y += lines) {
    DecodeRequest req;
    req.y0 = int(y);
    req.height = int(std::min(lines, uint64_t(d.height) - y));
    BTFC_RETURN_IF_ERROR(model->decode(req, band).with_context(input));
    BTFC_RETURN_IF_ERROR(band.check_finite(input));
    BTFC_RETURN_IF_ERROR(w.write_texels(y * width, uint64_t(req.height) * width, band.data()));
    if (progress) progress->advance();
  }
  if (progress) progress->finish();
  return {};
}

}  // namespace

Result<std::unique_ptr<fmf::ChunkSource>> open_raw_chunks(const std::string& path, uint32_t lines_per_chunk) {
  if (!is_raw_btfc(path, nullptr)) return invalid_argument(path + ": not a raw (uncompressed) .btfc");
  BTFC_ASSIGN_OR_RETURN(RawBands b, RawBands::open(path));
  const uint64_t per = uint64_t(std::max<uint32_t>(lines_per_chunk, 1)) * uint64_t(b.desc().width);
  return std::unique_ptr<fmf::ChunkSource>(std::make_unique<RawChunks>(std::move(b), per));
}

bool is_raw_btfc_file(const std::string& path) { return is_raw_btfc(path, nullptr); }

Result<BtfDesc> probe_btf(const std::string& path) {
  std::error_code ec;
  if (fs::is_directory(path, ec)) {
    BTFC_ASSIGN_OR_RETURN(ImageSetPlan plan, plan_image_set(path));
    return plan.desc;
  }
  if (!fs::exists(path, ec)) return io_error(path + ": no such file or directory");
  BtfDesc d;
  if (is_raw_btfc(path, &d)) return d;
  BTFC_ASSIGN_OR_RETURN(auto model, open_model(path));
  return model->desc();
}

Result<WorkFile> prepare_work_file(const std::string& input, const std::string& work_path, uint32_t lines, size_t max_bytes,
                                   Progress* progress) {
  const auto t0 = std::chrono::steady_clock::now();
  WorkFile wf;
  std::error_code ec;
  // An uncompressed BDI input is already a working file when its chunks fit the buffers.
  if (!fs::is_directory(input, ec) && is_bonn_btf(input)) {
    auto direct = BdiChunks::open(input);
    if (direct.ok() && direct->chunk_count(0) <= uint64_t(lines) * uint64_t(direct->desc().width)) {
      wf.path = input;
      wf.scale = direct->scale();
      return wf;
    }
  }
  BTFC_ASSIGN_OR_RETURN(BtfDesc d, probe_btf(input));
  const std::string fp = fingerprint(input);
  if (fs::exists(work_path, ec)) {
    auto old = BdiChunks::open(work_path);
    if (!old.ok()) {
      wf.note = old.status().message() + "; rebuilt";
    } else if (old->xml().find(fp) == std::string::npos) {
      wf.note = work_path + ": a working file of another source (or of a changed one); rebuilt";
    } else if (old->desc().abrdf_size() != d.abrdf_size() || old->desc().num_texels() != d.num_texels() ||
               old->chunk_count(0) > uint64_t(lines) * uint64_t(d.width)) {
      wf.note = work_path + ": a working file of another shape or chunking; rebuilt";
    } else {
      wf.path = work_path;
      wf.reused = true;
      wf.scale = old->scale();
      wf.note = work_path + ": complete working file of the same source reused";
      return wf;
    }
  }
  float scale = 1;
  for (int attempt = 0;; ++attempt) {
    char sbuf[32];
    std::snprintf(sbuf, sizeof sbuf, "%.9g", double(scale));
    const std::string xml = "<btfc_work scale=\"" + std::string(sbuf) + "\" " + fp + "/>";
    BTFC_ASSIGN_OR_RETURN(auto w, BdiWriter::create(work_path, d, lines, scale, xml));
    Status s = fill(input, *w, d, max_bytes, progress);
    if (s.ok()) {
      BTFC_RETURN_IF_ERROR(w->finish());
      break;
    }
    if (w->overflow() <= 0 || attempt >= 8) return s;
    // Headroom of 2^6 below the half maximum for values later in the input.
    const float want = w->overflow() * scale / 1024.0f;
    const float next = std::exp2(std::ceil(std::log2(std::isfinite(want) ? want : 1e30f)));
    wf.note += (wf.note.empty() ? "" : "; ") + std::string("values up to ") + std::to_string(w->overflow() * scale) +
               " exceed the half range: working file restarted with scale " + std::to_string(next);
    scale = std::max(next, scale * 2);
  }
  wf.path = work_path;
  wf.built = true;
  wf.scale = scale;
  wf.bytes_written = fs::file_size(work_path, ec);
  wf.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return wf;
}

Status decode_to_bdi(const Model& model, const std::string& path, size_t max_bytes) {
  const BtfDesc& d = model.desc();
  // The decoded band (float) plus its half copy: 6 bytes per value.
  const uint64_t lines = band_lines(d, 6, max_bytes);
  const std::string tmp = path + ".tmp-" + std::to_string(::getpid());
  {
    BTFC_ASSIGN_OR_RETURN(auto w, BdiWriter::create(tmp, d, uint32_t(std::min<uint64_t>(lines, 4)), 1.0f, "<btfc_decoded/>"));
    Btf band;
    for (uint64_t y = 0; y < uint64_t(d.height); y += lines) {
      DecodeRequest req;
      req.y0 = int(y);
      req.height = int(std::min(lines, uint64_t(d.height) - y));
      BTFC_RETURN_IF_ERROR(model.decode(req, band));
      Status s = w->write_texels(y * uint64_t(d.width), uint64_t(req.height) * uint64_t(d.width), band.data());
      if (!s.ok() && w->overflow() > 0)
        return unsupported(path + ": decoded values reach " + std::to_string(w->overflow()) +
                           ", beyond the half floats of a BDI file; decompress to .btfc instead");
      BTFC_RETURN_IF_ERROR(s);
    }
    BTFC_RETURN_IF_ERROR(w->finish());
  }
  std::error_code ec;
  fs::rename(tmp, path, ec);
  if (ec) {
    fs::remove(tmp, ec);
    return io_error(path + ": cannot rename the finished file into place");
  }
  return {};
}

}  // namespace btfc

namespace btfc {

Result<Metrics> compare_streamed(const BdiChunks& ref, const Model& model) {
  return compare_streamed(BdiChunkSource(ref), ref.desc(), ref.path(), model);
}

Result<Metrics> compare_streamed(const fmf::ChunkSource& ref, const BtfDesc& d, const std::string& path, const Model& model) {
  if (model.desc().abrdf_size() != d.abrdf_size() || model.desc().num_texels() != d.num_texels() || ref.rows() != d.abrdf_size() ||
      ref.texels() != d.num_texels())
    return invalid_argument(path + ": model shape differs from the reference BTF");
  if (ref.chunk_count(0) % uint64_t(d.width) != 0) return invalid_argument(path + ": reference chunks are not whole texel rows");
  double se = 0, sr = 0, mx = 0, peak = 0;
  std::vector<uint8_t> raw;
  std::vector<float> a;
  Btf band;
  for (uint64_t c = 0; c < ref.num_chunks(); ++c) {
    raw.resize(ref.raw_buffer_bytes(c));
    a.resize(ref.chunk_count(c) * ref.rows());
    BTFC_RETURN_IF_ERROR(ref.load(c, raw.empty() ? nullptr : raw.data(), a.data()));
    // Chunks are whole texel rows (BDI: formats.md 2.2; raw .btfc: open_raw_chunks).
    DecodeRequest req;
    req.y0 = int(ref.chunk_first(c) / uint64_t(d.width));
    req.height = int(ref.chunk_count(c) / uint64_t(d.width));
    BTFC_RETURN_IF_ERROR(model.decode(req, band));
    const float* b = band.data();
#pragma omp parallel for reduction(+ : se, sr) reduction(max : mx, peak) schedule(static)
    for (size_t i = 0; i < a.size(); ++i) {
      const double e = double(a[i]) - double(b[i]);
      se += e * e;
      sr += double(a[i]) * double(a[i]);
      mx = std::max(mx, std::fabs(e));
      peak = std::max(peak, double(a[i]));
    }
  }
  Metrics m;
  const double n = double(d.num_values());
  m.rmse = std::sqrt(se / n);
  m.rel_l2 = sr > 0 ? std::sqrt(se / sr) : (se > 0 ? INFINITY : 0);
  m.peak = (d.hdr || peak > 1) ? peak : 1.0;
  m.psnr = m.rmse > 0 ? 20 * std::log10(m.peak / m.rmse) : INFINITY;
  m.max_abs = mx;
  m.mean_ssim = NAN;
  return m;
}

}  // namespace btfc
