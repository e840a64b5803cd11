// Chunked writing and reading of uncompressed Bonn BDI files; see bdi_work.h for the contract.
#include "formats/bonn/bdi_work.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>
#if defined(__x86_64__)
#include <cpuid.h>
#include <immintrin.h>
#endif

#include <Imath/half.h>
#include <cmath>
#include <cstring>
#include <vector>
#include <limits>

#include "formats/bonn/bonn_io.h"

namespace btfc {

namespace {

#if defined(__x86_64__) && defined(__GNUC__)
#define BTFC_F16C_PATH 1
// The F16C loops are compiled for AVX + F16C whatever the build's flags and run only where the
// CPU has them (checked once), so a portable build (BTFC_NATIVE=OFF, core/cpu_dispatch.h) keeps
// the hardware conversion: software half rounding is several times slower per value. Both paths
// round to nearest even, so they give the same bits.
// F16C from CPUID leaf 1 (ECX bit 29) rather than __builtin_cpu_supports("f16c"), which clang
// before 15 does not know (the fuzz build, BTFC_FUZZ, is clang 14); "avx" also checks that the
// OS saves the YMM registers.
bool cpu_has_f16c() {
  static const bool yes = [] {
    unsigned a = 0, b = 0, c = 0, d = 0;
    return __builtin_cpu_supports("avx") && __get_cpuid(1, &a, &b, &c, &d) != 0 && (c & bit_F16C) != 0;
  }();
  return yes;
}

// Converts the first n - n % 8 values; returns how many. mx and nan as floats_to_half.
__attribute__((target("avx,f16c"))) size_t to_half_f16c(const float* src, size_t n, float inv_scale, uint16_t* dst, float& mx,
                                                        bool& nan) {
  size_t i = 0;
  __m256 vmax = _mm256_setzero_ps(), vnan = _mm256_setzero_ps();
  const __m256 vs = _mm256_set1_ps(inv_scale), sign = _mm256_set1_ps(-0.0f);
  for (; i + 8 <= n; i += 8) {
    const __m256 v = _mm256_mul_ps(_mm256_loadu_ps(src + i), vs);
    vmax = _mm256_max_ps(vmax, _mm256_andnot_ps(sign, v));
    vnan = _mm256_or_ps(vnan, _mm256_cmp_ps(v, v, _CMP_UNORD_Q));  // max() drops NaN, so track it apart
    _mm_storeu_si128(reinterpret_cast<__m128i*>(dst + i), _mm256_cvtps_ph(v, _MM_FROUND_TO_NEAREST_INT));
  }
  alignas(32) float lanes[8];
  _mm256_store_ps(lanes, vmax);
  for (float l : lanes) mx = std::max(mx, l);
  nan = nan || _mm256_movemask_ps(vnan) != 0;
  return i;
}

// Converts the first n - n % 8 values; returns how many. bad: nonzero if one was NaN / Inf.
__attribute__((target("avx,f16c"))) size_t to_floats_f16c(const uint16_t* src, size_t n, float scale, float* dst, uint16_t& bad) {
  size_t i = 0;
  const __m256 vs = _mm256_set1_ps(scale);
  const __m128i exp = _mm_set1_epi16(0x7c00);
  __m128i vbad = _mm_setzero_si128();
  for (; i + 8 <= n; i += 8) {
    const __m128i h = _mm_loadu_si128(reinterpret_cast<const __m128i*>(src + i));
    vbad = _mm_or_si128(vbad, _mm_cmpeq_epi16(_mm_and_si128(h, exp), exp));
    _mm256_storeu_ps(dst + i, _mm256_mul_ps(_mm256_cvtph_ps(h), vs));
  }
  bad = uint16_t(bad | _mm_movemask_epi8(vbad));
  return i;
}
#endif

}  // namespace

float floats_to_half(const float* src, size_t n, float inv_scale, uint16_t* dst) {
  float mx = 0;
  bool nan = false;
  size_t i = 0;
#ifdef BTFC_F16C_PATH
  if (cpu_has_f16c()) i = to_half_f16c(src, n, inv_scale, dst, mx, nan);
#endif
  for (; i < n; ++i) {
    const float v = src[i] * inv_scale;
    nan = nan || std::isnan(v);
    mx = std::max(mx, std::fabs(v));
    dst[i] = Imath::half(v).bits();
  }
  return nan ? std::numeric_limits<float>::quiet_NaN() : mx;
}

bool half_to_floats(const uint16_t* src, size_t n, float scale, float* dst) {
  size_t i = 0;
  uint16_t bad = 0;  // a half NaN / Inf has all exponent bits set
#ifdef BTFC_F16C_PATH
  if (cpu_has_f16c()) i = to_floats_f16c(src, n, scale, dst, bad);
#endif
  for (; i < n; ++i) {
    bad |= uint16_t((src[i] & 0x7c00) == 0x7c00);
    Imath::half h;
    h.setBits(src[i]);
    dst[i] = float(h) * scale;
  }
  return bad == 0;
}

// ---- BdiWriter ----

Result<std::unique_ptr<BdiWriter>> BdiWriter::create(const std::string& path, const BtfDesc& desc, uint32_t lines, float scale,
                                                     const std::string& xml) {
  BTFC_RETURN_IF_ERROR(desc.validate());
  if (lines == 0) return invalid_argument(path + ": BDI scan_lines_per_chunk must be >= 1");
  if (!(scale > 0) || !std::isfinite(scale)) return invalid_argument(path + ": BDI scale must be positive and finite");
  std::unique_ptr<BdiWriter> w(new BdiWriter());
  w->m_path = path;
  w->m_desc = desc;
  w->m_scale = scale;
  w->m_per_chunk = uint64_t(desc.width) * lines;
  w->m_chunks = (desc.num_texels() + w->m_per_chunk - 1) / w->m_per_chunk;
  const uint64_t full = w->m_per_chunk * desc.abrdf_size() * 2;
  if (full > 0xffffffffull)
    return invalid_argument(path + ": a BDI chunk of " + std::to_string(lines) + " scan lines would hold " + std::to_string(full) +
                            " bytes, more than its u32 chunk_bytes field allows; use fewer scan lines per chunk");
  // The header ends where the chunks begin: it is padded (a space after the XML) to an even
  // length, so that a chunk's half floats are 2-byte aligned and are decoded straight from the
  // mapping (read_decoded); at an odd offset every chunk took a zeroed copy and a pread, which
  // made a pass ~10 x slower (docs/benchmarks.md, out of core).
  for (std::string pad;; pad += ' ') {
    bonn::ByteSink sink(path);
    BTFC_RETURN_IF_ERROR(sink.open());
    sink.bytes(k_bdi_incomplete, 10);
    BonnMeta meta;
    meta.measurement_setup = "btfc working file";
    for (float& s : meta.rgb_scale_factor) s = scale;
    meta.xml = xml + pad;
    bonn::write_meta(sink, meta, desc.channels);
    bonn::write_sampling(sink, desc);
    sink.u32(uint32_t(desc.width));
    sink.u32(uint32_t(desc.height));
    sink.u32(lines);
    sink.u8(0);  // full, uncompressed
    std::vector<uint8_t> mask(desc.num_texels(), 1);
    sink.bytes(mask.data(), mask.size());
    sink.u32(0);  // no rotations
    BTFC_RETURN_IF_ERROR(sink.commit());
    struct stat st{};
    if (::stat(path.c_str(), &st) != 0 || st.st_size % 2 == 0 || !pad.empty()) break;
  }
  w->m_fd = ::open(path.c_str(), O_RDWR | O_CLOEXEC);
  if (w->m_fd < 0) return io_error(path + ": cannot reopen the working file (" + std::strerror(errno) + ")");
  const off_t header = ::lseek(w->m_fd, 0, SEEK_END);
  w->m_data0 = uint64_t(header);
  w->m_size = w->m_data0 + w->m_chunks * 4 + desc.num_texels() * desc.abrdf_size() * 2;
  if (::ftruncate(w->m_fd, off_t(w->m_size)) != 0)
    return io_error(path + ": cannot size the working file to " + std::to_string(w->m_size) + " bytes (" + std::strerror(errno) + ")");
  for (uint64_t c = 0; c < w->m_chunks; ++c) {
    const uint64_t n = std::min(w->m_per_chunk, desc.num_texels() - c * w->m_per_chunk);
    const uint32_t bytes = uint32_t(n * desc.abrdf_size() * 2);
    BTFC_RETURN_IF_ERROR(w->pwrite_all(&bytes, 4, w->m_data0 + c * (4 + full)));
  }
  return w;
}

BdiWriter::~BdiWriter() {
  if (m_fd >= 0) ::close(m_fd);
  if (!m_done && !m_path.empty()) ::unlink(m_path.c_str());
}

uint64_t BdiWriter::texel_offset(uint64_t t) const {
  const uint64_t c = t / m_per_chunk, full = m_per_chunk * m_desc.abrdf_size() * 2;
  return m_data0 + c * (4 + full) + 4 + (t % m_per_chunk) * m_desc.abrdf_size() * 2;
}

Status BdiWriter::pwrite_all(const void* p, size_t n, uint64_t off) {
  const uint8_t* b = static_cast<const uint8_t*>(p);
  while (n > 0) {
    const ssize_t r = ::pwrite(m_fd, b, n, off_t(off));
    if (r < 0 && errno == EINTR) continue;
    if (r <= 0) return io_error(m_path + ": writing " + std::to_string(n) + " bytes at offset " + std::to_string(off) + " failed (" +
                                std::strerror(errno) + ")");
    b += r, off += uint64_t(r), n -= size_t(r);
  }
  return {};
}

Status BdiWriter::write_texels(uint64_t t0, uint64_t n, const float* abrdfs) {
  if (t0 + n > m_desc.num_texels()) return invalid_argument(m_path + ": texels beyond the BTF");
  const size_t m = m_desc.abrdf_size();
  std::vector<uint16_t> h;
  // Runs of texels inside one chunk are contiguous on disk: one pwrite per run.
  for (uint64_t t = t0; t < t0 + n;) {
    const uint64_t run = std::min(t0 + n, (t / m_per_chunk + 1) * m_per_chunk) - t;
    h.resize(run * m);
    // Converted in parallel slices (the conversion, not the disk, bounds this loop with a warm page cache).
    const size_t total = run * m, slices = std::max<size_t>(1, std::min<size_t>(64, total >> 20));
    float mx = 0;
    bool nan = false;  // apart from the max: a max reduction may drop NaN
#pragma omp parallel for reduction(max : mx) reduction(|| : nan) schedule(static)
    for (size_t k = 0; k < slices; ++k) {
      const size_t a = total * k / slices, b = total * (k + 1) / slices;
      const float v = floats_to_half(abrdfs + (t - t0) * m + a, b - a, 1.0f / m_scale, h.data() + a);
      if (std::isnan(v)) nan = true;
      else mx = std::max(mx, v);
    }
    if (nan) mx = std::numeric_limits<float>::quiet_NaN();
    if (std::isnan(mx)) return corrupt_data(m_path + ": the input holds a NaN value");
    if (!(mx <= k_half_max)) {
      m_overflow = std::isfinite(mx) ? mx : std::numeric_limits<float>::infinity();
      return unsupported(m_path + ": value " + std::to_string(mx * m_scale) + " exceeds the half range at scale " + std::to_string(m_scale));
    }
    BTFC_RETURN_IF_ERROR(pwrite_all(h.data(), h.size() * 2, texel_offset(t)));
    t += run;
  }
  return {};
}

Status BdiWriter::write_images(uint64_t i0, uint64_t k, const float* images) {
  const uint64_t texels = m_desc.num_texels(), nc = uint64_t(m_desc.channels);
  if (i0 + k > m_desc.num_images()) return invalid_argument(m_path + ": images beyond the BTF");
  std::vector<float> seg(k * nc);
  std::vector<uint16_t> h(k * nc);
  for (uint64_t t = 0; t < texels; ++t) {
    for (uint64_t j = 0; j < k; ++j)
      for (uint64_t c = 0; c < nc; ++c) seg[j * nc + c] = images[(j * texels + t) * nc + c];
    const float mx = floats_to_half(seg.data(), seg.size(), 1.0f / m_scale, h.data());
    if (std::isnan(mx)) return corrupt_data(m_path + ": the input holds a NaN value");
    if (!(mx <= k_half_max)) {
      m_overflow = std::isfinite(mx) ? mx : std::numeric_limits<float>::infinity();
      return unsupported(m_path + ": value " + std::to_string(mx * m_scale) + " exceeds the half range at scale " + std::to_string(m_scale));
    }
    BTFC_RETURN_IF_ERROR(pwrite_all(h.data(), h.size() * 2, texel_offset(t) + i0 * nc * 2));
  }
  return {};
}

Status BdiWriter::finish() {
  if (::fdatasync(m_fd) != 0) return io_error(m_path + ": flushing the working file failed (" + std::strerror(errno) + ")");
  BTFC_RETURN_IF_ERROR(pwrite_all("!BDIF06R2!", 10, 0));
  if (::fdatasync(m_fd) != 0 || ::close(m_fd) != 0) {
    m_fd = -1;
    return io_error(m_path + ": flushing the working file failed (" + std::strerror(errno) + ")");
  }
  m_fd = -1;
  m_done = true;
  return {};
}

// ---- BdiChunks ----

Result<BdiChunks> BdiChunks::open(const std::string& path) {
  {
    BTFC_ASSIGN_OR_RETURN(bonn::ByteSource src, bonn::ByteSource::open(path));
    char head[10] = {0};
    if (src.size() >= 10) BTFC_RETURN_IF_ERROR(src.read_at(0, head, 10, "signature"));
    if (std::memcmp(head, k_bdi_incomplete, 10) == 0)
      return corrupt_data(path + ": incomplete working file from an interrupted btfc run (its completion signature was never "
                                 "written); not trusted: delete it, or let btfc rebuild it");
  }
  BTFC_ASSIGN_OR_RETURN(BonnInfo info, read_bonn_info(path));
  if (info.kind != BonnKind::bdi) return invalid_argument(path + ": a Bonn " + std::string(bonn_kind_name(info.kind)) + " file, not a BDI");
  if (info.bdi_compression != 0)
    return unsupported(path + ": only uncompressed full BDI files are read chunk by chunk (this one is " +
                       (info.bdi_compression == 1 ? "bzip2-compressed" : "sparse") + ")");
  BdiChunks b;
  b.m_path = path;
  b.m_desc = info.desc;
  b.m_xml = info.meta.xml;
  b.m_size = info.file_size;
  b.m_per_chunk = uint64_t(info.desc.width) * info.bdi_scan_lines_per_chunk;
  b.m_chunks = (info.desc.num_texels() + b.m_per_chunk - 1) / b.m_per_chunk;
  // Uncompressed chunks have fixed sizes (checked by read_bonn_info), so they end the file.
  b.m_data0 = info.file_size - b.m_chunks * 4 - info.desc.num_texels() * info.desc.abrdf_size() * 2;
  const size_t at = b.m_xml.find("<btfc_work ");
  if (at != std::string::npos) {
    const size_t s = b.m_xml.find("scale=\"", at);
    if (s != std::string::npos) b.m_scale = std::strtof(b.m_xml.c_str() + s + 7, nullptr);
    if (!(b.m_scale > 0) || !std::isfinite(b.m_scale)) return corrupt_data(path + ": btfc working file with an invalid scale in its meta xml");
  }
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return io_error(path + ": cannot open (" + std::strerror(errno) + ")");
  b.m_fd = std::shared_ptr<int>(new int(fd), [](int* p) {
    ::close(*p);
    delete p;
  });
  return b;
}

uint64_t BdiChunks::chunk_count(uint64_t c) const {
  return std::min(m_per_chunk, m_desc.num_texels() - c * m_per_chunk);
}

Status BdiChunks::read_raw(uint64_t c, uint16_t* dst) const {
  if (c >= m_chunks) return invalid_argument(m_path + ": BDI chunk " + std::to_string(c) + " does not exist");
  const uint64_t full = m_per_chunk * m_desc.abrdf_size() * 2;
  uint64_t off = m_data0 + c * (4 + full) + 4, n = chunk_bytes(c);
  uint8_t* p = reinterpret_cast<uint8_t*>(dst);
  while (n > 0) {
    const ssize_t r = ::pread(*m_fd, p, size_t(std::min<uint64_t>(n, uint64_t(1) << 30)), off_t(off));
    if (r < 0 && errno == EINTR) continue;
    if (r <= 0)
      return io_error(m_path + ": reading BDI chunk " + std::to_string(c) + " at offset " + std::to_string(off) + " failed" +
                      (r < 0 ? std::string(" (") + std::strerror(errno) + ")" : std::string(" (the file is shorter than its header says)")));
    p += r, off += uint64_t(r), n -= uint64_t(r);
  }
  return {};
}

Status BdiChunks::decode(uint64_t c, const uint16_t* raw, float* dst) const {
  const size_t n = size_t(chunk_count(c)) * m_desc.abrdf_size();
  if (half_to_floats(raw, n, m_scale, dst)) return {};
  size_t i = 0;  // a half NaN / Inf has all exponent bits set
  while ((raw[i] & 0x7c00) != 0x7c00) ++i;
  const uint64_t t = chunk_first(c) + i / m_desc.abrdf_size();
  return corrupt_data(m_path + ": BDI chunk " + std::to_string(c) + " holds a non-finite value at texel (" +
                      std::to_string(t % uint64_t(m_desc.width)) + ", " + std::to_string(t / uint64_t(m_desc.width)) + "), row " +
                      std::to_string(i % m_desc.abrdf_size()));
}

Status BdiChunks::read_decoded(uint64_t c, float* dst) const {
  if (c >= m_chunks) return invalid_argument(m_path + ": BDI chunk " + std::to_string(c) + " does not exist");
  const uint64_t full = m_per_chunk * m_desc.abrdf_size() * 2, off = m_data0 + c * (4 + full) + 4;
  const uint64_t page = uint64_t(::sysconf(_SC_PAGESIZE)), base = off / page * page, len = chunk_bytes(c) + (off - base);
  void* p = off % 2 ? MAP_FAILED : ::mmap(nullptr, size_t(len), PROT_READ, MAP_SHARED | MAP_POPULATE, *m_fd, off_t(base));
  if (p == MAP_FAILED) {  // odd offset (foreign file) or no mmap: read and decode a copy
    std::vector<uint16_t> raw(size_t(chunk_bytes(c) / 2));
    BTFC_RETURN_IF_ERROR(read_raw(c, raw.data()));
    return decode(c, raw.data(), dst);
  }
  Status s = decode(c, reinterpret_cast<const uint16_t*>(static_cast<const uint8_t*>(p) + (off - base)), dst);
  ::munmap(p, size_t(len));
  return s;
}

}  // namespace btfc
