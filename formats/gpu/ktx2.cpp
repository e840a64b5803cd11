#include "formats/gpu/ktx2.h"

#include <Imath/half.h>

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <numeric>

namespace btfc::gpu {
namespace {

const uint8_t k_id[12] = {0xAB, 'K', 'T', 'X', ' ', '2', '0', 0xBB, '\r', '\n', 0x1A, '\n'};
constexpr size_t k_header = 80, k_level_entry = 24;

void put32(std::vector<uint8_t>& b, size_t at, uint32_t v) {
  for (int i = 0; i < 4; ++i) b[at + size_t(i)] = uint8_t(v >> (8 * i));
}
void put64(std::vector<uint8_t>& b, size_t at, uint64_t v) {
  for (int i = 0; i < 8; ++i) b[at + size_t(i)] = uint8_t(v >> (8 * i));
}
uint32_t get32(const std::vector<uint8_t>& b, size_t at) {
  uint32_t v = 0;
  for (int i = 0; i < 4; ++i) v |= uint32_t(b[at + size_t(i)]) << (8 * i);
  return v;
}
uint64_t get64(const std::vector<uint8_t>& b, size_t at) { return uint64_t(get32(b, at)) | uint64_t(get32(b, at + 4)) << 32; }
size_t align(size_t x, size_t a) { return (x + a - 1) / a * a; }

// The Khronos basic data format descriptor for an uncompressed RGBA-ordered format.
std::vector<uint8_t> make_dfd(const FormatInfo& fi) {
  const uint32_t n = uint32_t(fi.channels), block = 24 + 16 * n;
  std::vector<uint8_t> d(4 + block, 0);
  put32(d, 0, 4 + block);                    // dfdTotalSize
  put32(d, 4, 0);                            // vendorId KHR (0), descriptorType basic (0)
  put32(d, 8, 2u | (block << 16));           // versionNumber 2 (KDF 1.3), descriptorBlockSize
  put32(d, 12, 1u | (1u << 8) | (1u << 16)); // colorModel RGBSDA, primaries BT709, transfer LINEAR, flags 0
  put32(d, 16, 0);                           // texel block 1x1x1x1
  put32(d, 20, n * uint32_t(fi.bytes_per_channel));  // bytesPlane0
  const uint32_t bits = 8 * uint32_t(fi.bytes_per_channel);
  const uint8_t channel_id[4] = {0, 1, 2, 15};  // R, G, B, A
  for (uint32_t s = 0; s < n; ++s) {
    const size_t at = 28 + 16 * size_t(s);
    uint32_t type = channel_id[s];
    if (fi.is_float) type |= 0x80 | 0x40;  // KHR_DF_SAMPLE_DATATYPE_FLOAT | SIGNED
    put32(d, at, (s * bits) | ((bits - 1) << 16) | (type << 24));
    put32(d, at + 4, 0);  // sample position
    uint32_t lower = 0, upper = 1;  // integer formats: 0 .. 1 (unnormalized)
    if (fi.is_float) lower = 0xBF800000u, upper = 0x3F800000u;  // -1.0f .. 1.0f
    if (fi.is_normalized) upper = (1u << bits) - 1;
    put32(d, at + 8, lower);
    put32(d, at + 12, upper);
  }
  return d;
}

std::vector<uint8_t> make_kvd(KeyValues kv) {
  kv.emplace_back("KTXwriter", std::string("btfc ") + BTFC_VERSION);
  std::sort(kv.begin(), kv.end());
  std::vector<uint8_t> out;
  for (const auto& [k, v] : kv) {
    const uint32_t len = uint32_t(k.size() + 1 + v.size() + 1);  // key NUL value NUL
    const size_t at = out.size();
    out.resize(align(at + 4 + len, 4), 0);
    put32(out, at, len);
    std::memcpy(out.data() + at + 4, k.data(), k.size());
    std::memcpy(out.data() + at + 4 + k.size() + 1, v.data(), v.size());
  }
  return out;
}

}  // namespace

std::vector<uint8_t> encode_ktx2(const GpuTexture& t, const KeyValues& kv) {
  const FormatInfo& fi = format_info(t.format);
  const uint32_t L = t.num_levels();
  const std::vector<uint8_t> dfd = make_dfd(fi), kvd = make_kvd(kv);
  const size_t dfd_at = k_header + k_level_entry * L, kvd_at = dfd_at + dfd.size();
  const size_t texel = size_t(fi.channels) * size_t(fi.bytes_per_channel);
  const size_t level_align = std::lcm(size_t(4), texel);
  std::vector<uint8_t> b(kvd_at + kvd.size(), 0);
  std::memcpy(b.data(), k_id, 12);
  put32(b, 12, fi.vk_format);
  put32(b, 16, uint32_t(fi.bytes_per_channel));
  put32(b, 20, t.width);
  put32(b, 24, t.height);
  put32(b, 28, 0);         // pixelDepth: 2D
  put32(b, 32, t.layers);  // 0 = not an array
  put32(b, 36, 1);         // faceCount
  put32(b, 40, L);
  put32(b, 44, 0);         // no supercompression
  put32(b, 48, uint32_t(dfd_at));
  put32(b, 52, uint32_t(dfd.size()));
  put32(b, 56, kvd.empty() ? 0 : uint32_t(kvd_at));
  put32(b, 60, uint32_t(kvd.size()));
  put64(b, 64, 0), put64(b, 72, 0);  // no supercompression global data
  std::memcpy(b.data() + dfd_at, dfd.data(), dfd.size());
  std::memcpy(b.data() + kvd_at, kvd.data(), kvd.size());
  for (uint32_t m = L; m-- > 0;) {  // smallest level first in the file
    const std::vector<uint8_t> data = t.level_bytes(m);
    const size_t at = align(b.size(), level_align);
    b.resize(at + data.size(), 0);
    std::memcpy(b.data() + at, data.data(), data.size());
    put64(b, k_header + k_level_entry * m, at);
    put64(b, k_header + k_level_entry * m + 8, data.size());
    put64(b, k_header + k_level_entry * m + 16, data.size());
  }
  return b;
}

Status write_ktx2(const GpuTexture& t, const std::string& path, const KeyValues& kv) {
  const std::vector<uint8_t> b = encode_ktx2(t, kv);
  const std::string tmp = path + ".tmp";
  {
    std::ofstream f(tmp, std::ios::binary | std::ios::trunc);
    if (!f) return io_error(path + ": cannot open for writing");
    f.write(reinterpret_cast<const char*>(b.data()), std::streamsize(b.size()));
    if (!f.good()) {
      f.close();
      std::remove(tmp.c_str());
      return io_error(path + ": write failed");
    }
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    std::remove(tmp.c_str());
    return io_error(path + ": cannot rename the temporary file into place");
  }
  return {};
}

Result<GpuTexture> decode_ktx2(const std::vector<uint8_t>& b, const std::string& what, KeyValues* kv) {
  auto bad = [&](const std::string& m) { return corrupt_data(what + ": KTX2: " + m); };
  if (b.size() < k_header || std::memcmp(b.data(), k_id, 12) != 0) return bad("not a KTX 2.0 file (identifier)");
  const uint32_t vk = get32(b, 12), type_size = get32(b, 16), w = get32(b, 20), h = get32(b, 24), depth = get32(b, 28);
  const uint32_t layers = get32(b, 32), faces = get32(b, 36), levels = get32(b, 40), sc = get32(b, 44);
  int fmt = -1;
  for (int i = 0; i <= int(TexFormat::rgba32f); ++i)
    if (format_info(TexFormat(i)).vk_format == vk) fmt = i;
  if (fmt < 0) return unsupported(what + ": KTX2 vkFormat " + std::to_string(vk) + " is not one btfc reads");
  const FormatInfo& fi = format_info(TexFormat(fmt));
  if (type_size != uint32_t(fi.bytes_per_channel)) return bad("typeSize " + std::to_string(type_size) + " disagrees with the format");
  if (w == 0 || h == 0 || depth != 0 || faces != 1 || sc != 0) return bad("only uncompressed 2D / 2D-array, one face, is read");
  if (levels == 0 || levels > 32 || ((w >> (levels - 1)) == 0 && (h >> (levels - 1)) == 0)) return bad("level count " + std::to_string(levels));
  if (uint64_t(w) * h * std::max(layers, 1u) > (1ull << 32)) return bad("implausible size");
  if (b.size() < k_header + k_level_entry * size_t(levels)) return bad("truncated level index");
  GpuTexture t;
  t.format = TexFormat(fmt), t.width = w, t.height = h, t.layers = layers;
  for (uint32_t m = 0; m < levels; ++m) {
    const uint64_t off = get64(b, k_header + k_level_entry * m), len = get64(b, k_header + k_level_entry * m + 8);
    const size_t n = t.level_values(m);
    if (len != n * size_t(fi.bytes_per_channel) || off > b.size() || len > b.size() - off)
      return bad("level " + std::to_string(m) + " has " + std::to_string(len) + " bytes at offset " + std::to_string(off) +
                 " (expected " + std::to_string(n * size_t(fi.bytes_per_channel)) + ", file " + std::to_string(b.size()) + ")");
    const uint8_t* p = b.data() + off;
    if (fi.is_integer) {
      std::vector<uint32_t> v(n);
      for (size_t i = 0; i < n; ++i) {
        uint32_t x = 0;
        for (int k = 0; k < fi.bytes_per_channel; ++k) x |= uint32_t(p[i * size_t(fi.bytes_per_channel) + size_t(k)]) << (8 * k);
        v[i] = x;
      }
      t.u.push_back(std::move(v));
    } else {
      std::vector<float> v(n);
      for (size_t i = 0; i < n; ++i) {
        const uint8_t* q = p + i * size_t(fi.bytes_per_channel);
        if (fi.is_normalized) v[i] = float(q[0]) / 255.f;
        else if (fi.bytes_per_channel == 2) {
          Imath::half hv;
          hv.setBits(uint16_t(q[0] | (q[1] << 8)));
          v[i] = float(hv);
        } else std::memcpy(&v[i], q, 4);
      }
      t.f.push_back(std::move(v));
    }
  }
  const uint32_t kvd_at = get32(b, 56), kvd_len = get32(b, 60);
  if (kv && kvd_len) {
    if (kvd_at > b.size() || kvd_len > b.size() - kvd_at) return bad("key/value data outside the file");
    for (size_t at = kvd_at; at + 4 <= size_t(kvd_at) + kvd_len;) {
      const uint32_t len = get32(b, at);
      if (len > size_t(kvd_at) + kvd_len - at - 4) return bad("key/value entry overruns its block");
      const char* s = reinterpret_cast<const char*>(b.data() + at + 4);
      const std::string entry(s, len);
      const size_t nul = entry.find('\0');
      if (nul == std::string::npos) return bad("key without terminator");
      std::string value = entry.substr(nul + 1);
      if (!value.empty() && value.back() == '\0') value.pop_back();
      kv->emplace_back(entry.substr(0, nul), value);
      at = align(at + 4 + len, 4);
    }
  }
  return t;
}

Result<GpuTexture> read_ktx2(const std::string& path, KeyValues* kv) {
  std::ifstream f(path, std::ios::binary);
  if (!f) return io_error(path + ": cannot open");
  std::vector<uint8_t> b((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  return decode_ktx2(b, path, kv);
}

}  // namespace btfc::gpu
