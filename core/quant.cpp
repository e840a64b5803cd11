// zq tensor encoding; see quant.h for the contract and docs/FORMAT.md for the bytes.
#include "core/quant.h"

#include <zstd.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <memory>
#include <string>

#include "core/dct.h"

namespace btfc::quant {
namespace {

constexpr uint32_t k_version = 1;
constexpr uint32_t k_flag_dct = 1;
constexpr uint64_t k_header = 32;
constexpr int32_t k_max_int = 1 << 30;
constexpr uint64_t k_max_decoded = uint64_t(1) << 36;
constexpr uint64_t k_max_ratio = uint64_t(1) << 17;

uint64_t ceil8(uint64_t n) { return (n + 7) / 8 * 8; }

uint32_t get_u32(const uint8_t* p) { return uint32_t(p[0]) | uint32_t(p[1]) << 8 | uint32_t(p[2]) << 16 | uint32_t(p[3]) << 24; }
uint64_t get_u64(const uint8_t* p) { return uint64_t(get_u32(p)) | uint64_t(get_u32(p + 4)) << 32; }
void put_u32(std::vector<uint8_t>& b, uint32_t v) {
  for (int i = 0; i < 4; ++i) b.push_back(uint8_t(v >> (8 * i)));
}
void put_u64(std::vector<uint8_t>& b, uint64_t v) { put_u32(b, uint32_t(v)), put_u32(b, uint32_t(v >> 32)); }

uint32_t zigzag(int32_t v) { return (uint32_t(v) << 1) ^ uint32_t(v >> 31); }
int32_t unzigzag(uint32_t u) { return int32_t(u >> 1) ^ -int32_t(u & 1); }

// rows and K of a shape (K = last dim), or false for a scalar / overflow.
bool rows_cols(const std::vector<uint64_t>& shape, uint64_t& rows, uint64_t& cols) {
  if (shape.empty()) return false;
  cols = shape.back();
  rows = 1;
  for (size_t i = 0; i + 1 < shape.size(); ++i)
    if (__builtin_mul_overflow(rows, shape[i], &rows)) return false;
  uint64_t n;
  return !__builtin_mul_overflow(rows, cols, &n);
}

struct Header {
  Layout layout;
  uint32_t byte_width = 0;
  uint64_t zsize = 0;
  uint64_t rows = 0, cols = 0, coeff_rows = 0;
};

Status parse_header(const uint8_t* p, uint64_t n, const std::vector<uint64_t>& shape, const std::string& what, Header& h) {
  auto bad = [&](const std::string& m) { return corrupt_data(what + ": zq " + m); };
  if (!rows_cols(shape, h.rows, h.cols)) return bad("needs 1..8 dims whose product fits 64 bits");
  if (n < k_header) return bad("payload of " + std::to_string(n) + " bytes is shorter than its 32-byte header");
  const uint32_t version = get_u32(p), flags = get_u32(p + 4);
  if (version != k_version) return bad("version " + std::to_string(version) + " (this btfc reads 1)");
  if (flags & ~k_flag_dct) return bad("reserved flag bits set");
  if (get_u32(p + 20) != 0) return bad("reserved field is not zero");
  h.layout.dct = flags & k_flag_dct;
  h.layout.width = get_u32(p + 8);
  h.layout.height = get_u32(p + 12);
  h.byte_width = get_u32(p + 16);
  h.zsize = get_u64(p + 24);
  if (h.byte_width < 1 || h.byte_width > 4) return bad("byte width " + std::to_string(h.byte_width) + " (1..4)");
  if (h.layout.dct) {
    if (h.layout.width == 0 || h.layout.height == 0 || uint64_t(h.layout.width) * h.layout.height != h.rows)
      return bad("DCT image " + std::to_string(h.layout.width) + "x" + std::to_string(h.layout.height) + " disagrees with " +
                 std::to_string(h.rows) + " rows");
    h.coeff_rows = ceil8(h.layout.width) * ceil8(h.layout.height);
  } else {
    if (h.layout.width || h.layout.height) return bad("image size set without the DCT flag");
    h.coeff_rows = h.rows;
  }
  if (h.cols > (n - k_header) / 4) return bad(std::to_string(h.cols) + " steps do not fit in " + std::to_string(n) + " bytes");
  if (h.zsize != n - k_header - 4 * h.cols)
    return bad("compressed size " + std::to_string(h.zsize) + " disagrees with the payload's " +
               std::to_string(n - k_header - 4 * h.cols) + " bytes after the steps");
  for (uint64_t k = 0; k < h.cols; ++k) {
    float s;
    const uint32_t bits = get_u32(p + k_header + 4 * k);
    std::memcpy(&s, &bits, 4);
    if (!std::isfinite(s) || !(s > 0)) return bad("step " + std::to_string(k) + " is not finite and positive");
  }
  return {};
}

// Image column -> padded image (edge repeated) -> 8x8 DCT coefficients in coded order
// (zigzag position, then block row-major), divided by the step and rounded.
void dct_column(const float* v, size_t stride, const Layout& L, double inv_step, int32_t* q, bool& overflow) {
  const size_t W = L.width, H = L.height, PW = ceil8(W), PH = ceil8(H), bx = PW / 8, nb = bx * (PH / 8);
  float block[64];
  double c[64];
  for (size_t b = 0; b < nb; ++b) {
    const size_t x0 = (b % bx) * 8, y0 = (b / bx) * 8;
    for (size_t y = 0; y < 8; ++y)
      for (size_t x = 0; x < 8; ++x) {
        const size_t sx = std::min(x0 + x, W - 1), sy = std::min(y0 + y, H - 1);
        block[y * 8 + x] = v[(sx + W * sy) * stride];
      }
    dct::fdct8x8(block, 8, c);
    for (size_t z = 0; z < 64; ++z) {
      const double r = std::round(c[dct::k_zigzag[z]] * inv_step);
      if (!(std::fabs(r) <= k_max_int)) overflow = true;
      q[z * nb + b] = overflow ? 0 : int32_t(r);
    }
  }
}

void idct_column(const int32_t* q, float step, const Layout& L, float* v, size_t stride) {
  const size_t W = L.width, H = L.height, PW = ceil8(W), PH = ceil8(H), bx = PW / 8, nb = bx * (PH / 8);
  double c[64];
  float block[64];
  for (size_t b = 0; b < nb; ++b) {
    for (size_t z = 0; z < 64; ++z) c[dct::k_zigzag[z]] = double(q[z * nb + b]) * double(step);
    dct::idct8x8(c, block, 8);
    const size_t x0 = (b % bx) * 8, y0 = (b / bx) * 8;
    for (size_t y = 0; y < 8 && y0 + y < H; ++y)
      for (size_t x = 0; x < 8 && x0 + x < W; ++x) v[(x0 + x + W * (y0 + y)) * stride] = block[y * 8 + x];
  }
}

// Values from integers (row-major [rows, cols] out).
void dequantize(const Header& h, const int32_t* q, const float* steps, float* out) {
  for (uint64_t k = 0; k < h.cols; ++k) {
    const int32_t* qk = q + k * h.coeff_rows;
    if (h.layout.dct) {
      idct_column(qk, steps[k], h.layout, out + k, h.cols);
    } else {
      for (uint64_t r = 0; r < h.rows; ++r) out[r * h.cols + k] = float(qk[r]) * steps[k];
    }
  }
}

// One zstd frame of the planes. Planes of k_two_jobs_from bytes or more (fmf's factors at ranks
// in the hundreds: 25-40 MB) are compressed as two jobs of half the planes each on two zstd
// workers, the second reloading the last quarter window of the first (ZSTD_c_overlapLog 7): at
// level 19 one such call took 6-8.5 s on one core and was most of a byte-budget probe's time at
// large ranks; two jobs took 3.5-5 s for 0.1-0.3 % more bytes (25 and 31 MB of 6-bit planes,
// docs/benchmarks.md). The jobs depend on the size only, so the bytes are the same on every
// machine; readers see an ordinary frame. A libzstd without threads: one job, as below.
constexpr size_t k_two_jobs_from = size_t(8) << 20;
Result<size_t> compress_planes(const std::vector<uint8_t>& planes, int level, std::vector<uint8_t>& z) {
  if (planes.size() < k_two_jobs_from) {
    const size_t zn = ZSTD_compress(z.data(), z.size(), planes.data(), planes.size(), level);
    if (ZSTD_isError(zn)) return codec_error(std::string("zstd: ") + ZSTD_getErrorName(zn));
    return zn;
  }
  std::unique_ptr<ZSTD_CCtx, size_t (*)(ZSTD_CCtx*)> cctx(ZSTD_createCCtx(), ZSTD_freeCCtx);
  if (!cctx) return codec_error("zstd: no compression context");
  ZSTD_CCtx* c = cctx.get();
  const size_t job = (planes.size() / 2 + (size_t(1) << 20) - 1) >> 20 << 20;  // half, rounded up to 1 MiB
  if (ZSTD_isError(ZSTD_CCtx_setParameter(c, ZSTD_c_compressionLevel, level)))
    return codec_error("zstd: compression level " + std::to_string(level) + " refused");
  if (!ZSTD_isError(ZSTD_CCtx_setParameter(c, ZSTD_c_nbWorkers, 2))) {
    ZSTD_CCtx_setParameter(c, ZSTD_c_jobSize, int(job));
    ZSTD_CCtx_setParameter(c, ZSTD_c_overlapLog, 7);
  }
  const size_t zn = ZSTD_compress2(c, z.data(), z.size(), planes.data(), planes.size());
  if (ZSTD_isError(zn)) return codec_error(std::string("zstd: ") + ZSTD_getErrorName(zn));
  return zn;
}

}  // namespace

Status check_header(const uint8_t* data, uint64_t data_bytes, const std::vector<uint64_t>& shape, const std::string& what) {
  Header h;
  return parse_header(data, data_bytes, shape, what, h);
}

Result<Tensor> encode(std::string name, std::vector<uint64_t> shape, const float* values, const std::vector<float>& steps,
                      const Layout& layout, int zstd_level, std::vector<float>* dequantized) {
  Header h;
  h.layout = layout;
  const std::string what = "tensor '" + name + "'";
  if (!rows_cols(shape, h.rows, h.cols)) return invalid_argument(what + ": zq needs 1..8 dims");
  if (steps.size() != h.cols) return invalid_argument(what + ": " + std::to_string(steps.size()) + " steps for " + std::to_string(h.cols) + " columns");
  for (float s : steps)
    if (!std::isfinite(s) || !(s > 0)) return invalid_argument(what + ": quantisation steps must be finite and positive");
  if (layout.dct) {
    if (uint64_t(layout.width) * layout.height != h.rows || layout.width == 0)
      return invalid_argument(what + ": DCT image size disagrees with the rows");
    h.coeff_rows = ceil8(layout.width) * ceil8(layout.height);
  } else {
    h.coeff_rows = h.rows;
  }
  // Column-major integers: q[k * coeff_rows + i].
  std::vector<int32_t> q(static_cast<size_t>(h.coeff_rows * h.cols));
  bool overflow = false;
  for (uint64_t k = 0; k < h.cols; ++k) {
    const double inv = 1.0 / double(steps[k]);
    if (layout.dct) {
      dct_column(values + k, h.cols, layout, inv, &q[k * h.coeff_rows], overflow);
    } else {
      for (uint64_t r = 0; r < h.rows; ++r) {
        const float v = values[r * h.cols + k];
        const double x = std::round(double(v) * inv);
        if (!(std::fabs(x) <= k_max_int)) overflow = true;  // also catches NaN
        q[k * h.coeff_rows + r] = overflow ? 0 : int32_t(x);
      }
    }
  }
  if (overflow) return invalid_argument(what + ": a value is not finite or needs more than 31 bits at its step");
  uint32_t mx = 0;
  for (int32_t v : q) mx = std::max(mx, zigzag(v));
  h.byte_width = mx < (1u << 8) ? 1 : mx < (1u << 16) ? 2 : mx < (1u << 24) ? 3 : 4;
  std::vector<uint8_t> planes(q.size() * h.byte_width);
  uint8_t* o = planes.data();
  for (uint64_t k = 0; k < h.cols; ++k)
    for (uint32_t b = 0; b < h.byte_width; ++b)
      for (uint64_t i = 0; i < h.coeff_rows; ++i) *o++ = uint8_t(zigzag(q[k * h.coeff_rows + i]) >> (8 * b));
  std::vector<uint8_t> z(ZSTD_compressBound(planes.size()));
  const Result<size_t> compressed = compress_planes(planes, zstd_level, z);
  if (!compressed.ok()) return codec_error(what + ": " + compressed.status().message());
  const size_t zn = compressed.value();
  Tensor t;
  t.name = std::move(name);
  t.dtype = DType::zq;
  t.shape = std::move(shape);
  std::vector<uint8_t>& b = t.bytes;
  put_u32(b, k_version), put_u32(b, layout.dct ? k_flag_dct : 0);
  put_u32(b, layout.dct ? layout.width : 0), put_u32(b, layout.dct ? layout.height : 0);
  put_u32(b, h.byte_width), put_u32(b, 0), put_u64(b, zn);
  for (float s : steps) put_u32(b, std::bit_cast<uint32_t>(s));
  b.insert(b.end(), z.begin(), z.begin() + ptrdiff_t(zn));
  if (dequantized) {
    dequantized->resize(size_t(h.rows * h.cols));
    dequantize(h, q.data(), steps.data(), dequantized->data());
  }
  return t;
}

Result<Decoded> decode_ints(const Tensor& t, const std::string& what) {
  if (t.dtype != DType::zq) return invalid_argument(what + ": dtype " + dtype_name(t.dtype) + " is not zq");
  Header h;
  BTFC_RETURN_IF_ERROR(parse_header(t.bytes.data(), t.bytes.size(), t.shape, what, h));
  auto bad = [&](const std::string& m) { return corrupt_data(what + ": zq " + m); };
  uint64_t ints, want;
  if (__builtin_mul_overflow(h.coeff_rows, h.cols, &ints) || __builtin_mul_overflow(ints, uint64_t(h.byte_width), &want) ||
      want > k_max_decoded)
    return bad("declared size is too large");
  if (h.zsize == 0 && want != 0) return bad("compressed data is empty");
  if (want / k_max_ratio > h.zsize)  // zstd cannot expand this much: a decompression bomb
    return bad(std::to_string(want) + " decoded bytes from " + std::to_string(h.zsize) + " compressed is more than zstd produces");
  const uint8_t* z = t.bytes.data() + k_header + 4 * h.cols;
  Decoded d;
  d.layout = h.layout, d.rows = h.rows, d.cols = h.cols, d.coeff_rows = h.coeff_rows;
  d.steps.resize(size_t(h.cols));
  for (uint64_t k = 0; k < h.cols; ++k) {
    const uint32_t bits = get_u32(t.bytes.data() + k_header + 4 * k);
    std::memcpy(&d.steps[k], &bits, 4);
  }
  if (want == 0) return d;
  const unsigned long long declared = ZSTD_getFrameContentSize(z, size_t(h.zsize));
  if (declared == ZSTD_CONTENTSIZE_ERROR) return bad("compressed data is not a zstd frame");
  if (declared != ZSTD_CONTENTSIZE_UNKNOWN && declared != want)
    return bad("zstd frame declares " + std::to_string(declared) + " bytes, the shape needs " + std::to_string(want));
  if (ZSTD_findFrameCompressedSize(z, size_t(h.zsize)) != h.zsize) return bad("compressed data is truncated or has trailing bytes");
  std::vector<uint8_t> planes(static_cast<size_t>(want));
  const size_t got = ZSTD_decompress(planes.data(), planes.size(), z, size_t(h.zsize));
  if (ZSTD_isError(got)) return bad(std::string("zstd: ") + ZSTD_getErrorName(got));
  if (got != want) return bad("zstd frame holds " + std::to_string(got) + " bytes, the shape needs " + std::to_string(want));
  d.q.assign(size_t(ints), 0);
  std::vector<uint32_t> u(static_cast<size_t>(h.coeff_rows));
  const uint8_t* p = planes.data();
  for (uint64_t k = 0; k < h.cols; ++k) {
    std::fill(u.begin(), u.end(), 0u);
    for (uint32_t b = 0; b < h.byte_width; ++b)
      for (uint64_t i = 0; i < h.coeff_rows; ++i) u[i] |= uint32_t(*p++) << (8 * b);
    for (uint64_t i = 0; i < h.coeff_rows; ++i) {
      const int32_t v = unzigzag(u[i]);
      if (v > k_max_int || v < -k_max_int) return bad("integer beyond +-2^30");
      d.q[k * h.coeff_rows + i] = v;
    }
  }
  return d;
}

Result<std::vector<float>> decode(const Tensor& t, const std::string& what) {
  BTFC_ASSIGN_OR_RETURN(Decoded d, decode_ints(t, what));
  Header h;
  h.layout = d.layout, h.rows = d.rows, h.cols = d.cols, h.coeff_rows = d.coeff_rows;
  std::vector<float> out(static_cast<size_t>(d.rows * d.cols));
  if (!out.empty()) dequantize(h, d.q.data(), d.steps.data(), out.data());
  for (float v : out)
    if (!std::isfinite(v)) return corrupt_data(what + ": zq values overflow float");
  return out;
}

}  // namespace btfc::quant
