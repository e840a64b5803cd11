// Bonn .btf common header and byte I/O (formats.md 2.2: BTFLIB read_meta_data.m,
// read_bidir_sampling.m, read_common_header.m, identify_signature.m).
#include <Imath/half.h>
#include <fcntl.h>
#include <unistd.h>

#include <cmath>
#include <cstring>
#include <sstream>

#include "formats/bonn/bonn_io.h"

namespace btfc {

const char* bonn_kind_name(BonnKind k) {
  switch (k) {
    case BonnKind::dfmf: return "DFMF";
    case BonnKind::fmf: return "FMF";
    case BonnKind::pvf: return "PVF";
    case BonnKind::bdi: return "BDI";
  }
  return "?";
}

std::vector<std::pair<std::string, std::string>> BonnInfo::notes() const {
  std::vector<std::pair<std::string, std::string>> n;
  n.emplace_back("bonn.signature", signature);
  n.emplace_back("bonn.format", bonn_kind_name(kind));
  n.emplace_back("bonn.meta_version", std::to_string(meta.struct_version));
  if (!meta.measurement_setup.empty()) n.emplace_back("bonn.measurement_setup", meta.measurement_setup);
  if (color_model >= 0) n.emplace_back("bonn.color_model", std::to_string(color_model));
  std::string sizes, comps;
  for (size_t i = 0; i < scalar_sizes.size(); ++i) {
    if (i) sizes += ',', comps += ',';
    sizes += scalar_sizes[i] == 2 ? "half" : scalar_sizes[i] == 4 ? "float" : "double";
    comps += std::to_string(components[i]);
  }
  if (kind != BonnKind::bdi) {
    n.emplace_back("bonn.precision", sizes);
    n.emplace_back("bonn.components", comps);
  } else {
    n.emplace_back("bonn.bdi_compression", bdi_compression == 0 ? "full" : bdi_compression == 1 ? "bzip2" : "sparse");
    n.emplace_back("bonn.bdi_stored_texels", std::to_string(bdi_stored_texels));
  }
  n.emplace_back("bonn.rotations", std::to_string(rotations.size()));
  std::ostringstream dev;
  dev << (dome1 ? "yes" : "no");
  if (dome1_max_dev_deg >= 0) dev << " (largest deviation " << dome1_max_dev_deg << " deg)";
  n.emplace_back("bonn.ubo2014_dome1", dev.str());
  n.emplace_back("bonn.row_order", "as stored (y = file row; btf.hh would flip y <-> H-1-y)");
  return n;
}

namespace bonn {

bool mul_ok(uint64_t a, uint64_t b, uint64_t& out) { return !__builtin_mul_overflow(a, b, &out); }

// ---- ByteSource ----

Result<ByteSource> ByteSource::open(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return io_error(path + ": cannot open (" + std::strerror(errno) + ")");
  ByteSource s;
  s.m_path = path;
  s.m_fd = std::shared_ptr<int>(new int(fd), [](int* p) {
    ::close(*p);
    delete p;
  });
  const off_t end = ::lseek(fd, 0, SEEK_END);
  if (end < 0) return io_error(path + ": cannot determine the file size");
  s.m_size = uint64_t(end);
  return s;
}

Status ByteSource::need(uint64_t n, const std::string& field) const {
  if (n <= remaining()) return {};
  return corrupt(field + " needs " + std::to_string(n) + " bytes at offset " + std::to_string(m_pos) + ", the file has " +
                 std::to_string(remaining()) + " left");
}

Status ByteSource::read_at(uint64_t offset, void* dst, uint64_t n, const std::string& field) const {
  uint8_t* p = static_cast<uint8_t*>(dst);
  while (n > 0) {
    const ssize_t r = ::pread(*m_fd, p, size_t(std::min<uint64_t>(n, uint64_t(1) << 30)), off_t(offset));
    if (r < 0 && errno == EINTR) continue;
    if (r <= 0) return io_error(m_path + ": reading " + field + " at offset " + std::to_string(offset) + " failed");
    p += r, offset += uint64_t(r), n -= uint64_t(r);
  }
  return {};
}

Status ByteSource::bytes(void* dst, uint64_t n, const std::string& field) {
  BTFC_RETURN_IF_ERROR(need(n, field));
  BTFC_RETURN_IF_ERROR(read_at(m_pos, dst, n, field));
  m_pos += n;
  return {};
}

Status ByteSource::skip(uint64_t n, const std::string& field) {
  BTFC_RETURN_IF_ERROR(need(n, field));
  m_pos += n;
  return {};
}

Status ByteSource::scalars(float* dst, uint64_t n, int ss, const std::string& field) {
  uint64_t total;
  if (!mul_ok(n, uint64_t(ss), total)) return corrupt(field + " size overflows");
  BTFC_RETURN_IF_ERROR(need(total, field));
  if (ss == 4) return bytes(dst, total, field);
  // Convert through a bounded staging buffer (1 M scalars).
  std::vector<uint8_t> buf;
  const uint64_t step = uint64_t(1) << 20;
  for (uint64_t i = 0; i < n; i += step) {
    const uint64_t k = std::min(step, n - i);
    buf.resize(size_t(k) * size_t(ss));
    BTFC_RETURN_IF_ERROR(bytes(buf.data(), buf.size(), field));
    if (ss == 2) {
      const uint16_t* h = reinterpret_cast<const uint16_t*>(buf.data());
      for (uint64_t j = 0; j < k; ++j) {
        Imath::half v;
        v.setBits(h[j]);
        dst[i + j] = float(v);
      }
    } else {
      const double* d = reinterpret_cast<const double*>(buf.data());
      for (uint64_t j = 0; j < k; ++j) dst[i + j] = float(d[j]);
    }
  }
  return {};
}

// ---- ByteSink ----

ByteSink::~ByteSink() {
  if (m_f) {
    std::fclose(m_f);
    std::remove(m_tmp.c_str());
  }
}

Status ByteSink::open() {
  m_tmp = m_path + ".tmp-" + std::to_string(::getpid());
  m_f = std::fopen(m_tmp.c_str(), "wb");
  if (!m_f) return io_error(m_path + ": cannot create " + m_tmp + " (" + std::strerror(errno) + ")");
  std::setvbuf(m_f, nullptr, _IOFBF, 1 << 20);
  return {};
}

void ByteSink::bytes(const void* p, size_t n) {
  if (!m_failed && n && std::fwrite(p, 1, n, m_f) != n) m_failed = true;
}

Status ByteSink::scalars(const float* p, size_t n, bool half, const std::string& field) {
  if (!half) {
    for (size_t i = 0; i < n; ++i)
      if (!std::isfinite(p[i])) return invalid_argument(m_path + ": " + field + " holds a non-finite value");
    bytes(p, n * 4);
    return {};
  }
  std::vector<uint16_t> buf;
  const size_t step = size_t(1) << 20;
  for (size_t i = 0; i < n; i += step) {
    const size_t k = std::min(step, n - i);
    buf.resize(k);
    for (size_t j = 0; j < k; ++j) {
      const float v = p[i + j];
      if (!(std::fabs(v) <= 65504.0f))
        return invalid_argument(m_path + ": " + field + " value " + std::to_string(v) +
                                " is outside the half range (65504): write float scalars (btfc convert MODEL.btfc -o OUT.btf --precision float)");
      buf[j] = Imath::half(v).bits();
    }
    bytes(buf.data(), k * 2);
  }
  return {};
}

Status ByteSink::commit() {
  const bool ok = !m_failed && std::fflush(m_f) == 0;
  const bool closed = std::fclose(m_f) == 0;
  m_f = nullptr;
  if (!ok || !closed) {
    std::remove(m_tmp.c_str());
    return io_error(m_path + ": write failed");
  }
  if (std::rename(m_tmp.c_str(), m_path.c_str()) != 0) {
    std::remove(m_tmp.c_str());
    return io_error(m_path + ": cannot rename " + m_tmp + " (" + std::strerror(errno) + ")");
  }
  return {};
}

// ---- signature ----

std::string match_signature(const uint8_t* head, size_t n) {
  // Longest first (identify_signature.m): "!FMF06FC" is a prefix of "!FMF06FCR".
  static const char* k_sigs[] = {"!DFMF08FCR", "!FMF12FCER", "!BDIF06R2!", "!FMF06FCR", "!PVF06FCR", "!FMF06FC", "!PVF06FC"};
  for (const char* s : k_sigs) {
    const size_t len = std::strlen(s);
    if (n >= len && std::memcmp(head, s, len) == 0) return s;
  }
  return "";
}

// ---- meta block ----

static std::string fixed_string(const char* p, size_t n) {
  size_t len = 0;
  while (len < n && p[len] != 0) ++len;
  return std::string(p, len);
}

Status read_meta(ByteSource& src, BonnMeta& m) {
  const uint64_t start = src.pos();
  uint32_t struct_size = 0;
  BTFC_RETURN_IF_ERROR(src.u32(struct_size, "meta struct_size"));
  BTFC_RETURN_IF_ERROR(src.u32(m.struct_version, "meta struct_version"));
  if (m.struct_version < 1 || m.struct_version > 4)
    return unsupported(src.path() + ": meta struct_version " + std::to_string(m.struct_version) + " (1-4 supported)");
  // The block must fit the file as a whole before its parts are read.
  BTFC_RETURN_IF_ERROR(src.need(uint64_t(struct_size) >= 8 ? struct_size - 8 : 0, "meta block (struct_size " + std::to_string(struct_size) + ")"));
  char text[80];
  BTFC_RETURN_IF_ERROR(src.bytes(text, 80, "meta measurement_setup"));
  m.measurement_setup = fixed_string(text, 80);
  BTFC_RETURN_IF_ERROR(src.bytes(text, 80, "meta image_sensor"));
  m.image_sensor = fixed_string(text, 80);
  BTFC_RETURN_IF_ERROR(src.bytes(text, 80, "meta light_source"));
  m.light_source = fixed_string(text, 80);
  BTFC_RETURN_IF_ERROR(src.f32(m.ppmm, "meta ppmm"));
  BTFC_RETURN_IF_ERROR(src.bytes(m.rgb_scale_factor, 12, "meta rgb_scale_factor"));
  if (m.struct_version > 1) BTFC_RETURN_IF_ERROR(src.u32(m.cosine_flag, "meta cosine_flag"));
  if (m.struct_version > 2) {
    uint32_t n = 0;
    BTFC_RETURN_IF_ERROR(src.u32(n, "meta xml_size"));
    BTFC_RETURN_IF_ERROR(src.need(n, "meta xml (xml_size " + std::to_string(n) + ")"));
    m.xml.resize(n);
    BTFC_RETURN_IF_ERROR(src.bytes(m.xml.data(), n, "meta xml"));
  }
  m.channel_names.clear();
  if (m.struct_version > 3) {
    uint32_t nc = 0;
    BTFC_RETURN_IF_ERROR(src.u32(nc, "meta num_channels"));
    if (nc == 0 || nc > 64) return src.corrupt("meta num_channels " + std::to_string(nc) + " outside [1, 64]");
    for (uint32_t c = 0; c < nc; ++c) {
      const std::string f = "meta channel " + std::to_string(c) + " name";
      uint32_t len = 0;
      BTFC_RETURN_IF_ERROR(src.u32(len, f + " length"));
      BTFC_RETURN_IF_ERROR(src.need(len, f + " (length " + std::to_string(len) + ")"));
      std::string s(len, '\0');
      BTFC_RETURN_IF_ERROR(src.bytes(s.data(), len, f));
      m.channel_names.push_back(fixed_string(s.data(), s.size()));
    }
  } else {
    m.channel_names = {"R", "G", "B"};
  }
  const uint64_t consumed = src.pos() - start;
  if (consumed != struct_size)
    return src.corrupt("meta struct_size " + std::to_string(struct_size) + " disagrees with the " + std::to_string(consumed) +
                       " bytes of a version " + std::to_string(m.struct_version) + " meta block");
  return {};
}

void write_meta(ByteSink& out, const BonnMeta& m, int channels) {
  std::vector<std::string> names = m.channel_names;
  if (int(names.size()) != channels) {
    names.clear();
    if (channels == 3) names = {"R", "G", "B"};
    else
      for (int c = 0; c < channels; ++c) names.push_back(std::to_string(c));  // readers parse non-RGB names as numbers
  }
  uint32_t size = 4 + 4 + 240 + 4 + 12 + 4 + 4 + uint32_t(m.xml.size()) + 4;
  for (const std::string& n : names) size += 4 + uint32_t(n.size());
  out.u32(size);
  out.u32(4);  // always version 4: it is the only one carrying the channel count
  for (const std::string* s : {&m.measurement_setup, &m.image_sensor, &m.light_source}) {
    char text[80] = {0};
    std::memcpy(text, s->data(), std::min<size_t>(s->size(), 79));
    out.bytes(text, 80);
  }
  out.f32(m.ppmm);
  out.bytes(m.rgb_scale_factor, 12);
  out.u32(m.cosine_flag);
  out.u32(uint32_t(m.xml.size()));
  out.bytes(m.xml.data(), m.xml.size());
  out.u32(uint32_t(names.size()));
  for (const std::string& n : names) {
    out.u32(uint32_t(n.size()));
    out.bytes(n.data(), n.size());
  }
}

// ---- sampling ----

Status read_sampling(ByteSource& src, BonnInfo& info) {
  uint32_t nv = 0;
  BTFC_RETURN_IF_ERROR(src.u32(nv, "sampling num_views"));
  if (nv == 0) return src.corrupt("sampling num_views is 0");
  // Each view takes at least 12 bytes (theta, phi, nL): bound nV before allocating.
  BTFC_RETURN_IF_ERROR(src.need(uint64_t(nv) * 12, "sampling (num_views " + std::to_string(nv) + ")"));
  info.desc.views.dirs.clear();
  info.desc.lights.dirs.clear();
  std::vector<float> first, cur;
  for (uint32_t v = 0; v < nv; ++v) {
    const std::string f = "sampling view " + std::to_string(v);
    float tp[2];
    uint32_t nl = 0;
    BTFC_RETURN_IF_ERROR(src.bytes(tp, 8, f + " theta/phi"));
    BTFC_RETURN_IF_ERROR(src.u32(nl, f + " num_lights"));
    if (nl == 0) return src.corrupt(f + " num_lights is 0");
    if (v > 0 && nl != first.size() / 2)
      return src.corrupt(f + " num_lights " + std::to_string(nl) + " differs from view 0's " + std::to_string(first.size() / 2) +
                         " (the light list must be the same for every view)");
    BTFC_RETURN_IF_ERROR(src.need(uint64_t(nl) * 8, f + " light list (num_lights " + std::to_string(nl) + ")"));
    std::vector<float>& dst = v == 0 ? first : cur;
    dst.resize(size_t(nl) * 2);
    BTFC_RETURN_IF_ERROR(src.bytes(dst.data(), uint64_t(nl) * 8, f + " light list"));
    if (v > 0 && std::memcmp(first.data(), cur.data(), first.size() * 4) != 0)
      return src.corrupt(f + " light list differs from view 0's (the light list must be the same for every view)");
    if (!std::isfinite(tp[0]) || !std::isfinite(tp[1])) return src.corrupt(f + " direction is not finite");
    info.desc.views.dirs.push_back(dir_from_theta_phi(tp[0], tp[1]));
  }
  for (size_t l = 0; l < first.size() / 2; ++l) {
    if (!std::isfinite(first[2 * l]) || !std::isfinite(first[2 * l + 1]))
      return src.corrupt("sampling light " + std::to_string(l) + " direction is not finite");
    info.desc.lights.dirs.push_back(dir_from_theta_phi(first[2 * l], first[2 * l + 1]));
  }
  return {};
}

void write_sampling(ByteSink& out, const BtfDesc& d) {
  std::vector<float> lights;
  for (const Vec3& l : d.lights.dirs) {
    double t, p;
    dir_to_theta_phi(l, t, p);
    lights.push_back(float(t));
    lights.push_back(float(p));
  }
  out.u32(uint32_t(d.num_views()));
  for (const Vec3& v : d.views.dirs) {
    double t, p;
    dir_to_theta_phi(v, t, p);
    out.f32(float(t));
    out.f32(float(p));
    out.u32(uint32_t(d.num_lights()));
    out.bytes(lights.data(), lights.size() * 4);
  }
}

Status read_size(ByteSource& src, BonnInfo& info) {
  uint32_t w = 0, h = 0;
  BTFC_RETURN_IF_ERROR(src.u32(w, "width"));
  BTFC_RETURN_IF_ERROR(src.u32(h, "height"));
  if (w == 0 || h == 0 || w > (1u << 20) || h > (1u << 20))
    return src.corrupt("size " + std::to_string(w) + " x " + std::to_string(h) + " outside [1, 2^20] per axis");
  info.desc.width = int(w);
  info.desc.height = int(h);
  return {};
}

Status read_rotations(ByteSource& src, BonnInfo& info) {
  uint32_t n = 0;
  BTFC_RETURN_IF_ERROR(src.u32(n, "num_rotations"));
  BTFC_RETURN_IF_ERROR(src.need(uint64_t(n) * 36, "rotations (num_rotations " + std::to_string(n) + ")"));
  info.rotations.resize(n);
  for (uint32_t i = 0; i < n; ++i) BTFC_RETURN_IF_ERROR(src.bytes(info.rotations[i].data(), 36, "rotation " + std::to_string(i)));
  return {};
}

Status finish_desc(const ByteSource& src, BonnInfo& info) {
  BtfDesc& d = info.desc;
  d.channels = int(info.meta.channel_names.size());
  d.hdr = true;  // Bonn data are linear radiance-like floats
  d.lights.identify();
  d.views.identify();
  info.dome1 = d.lights.name == "ubo2014" && d.views.name == "ubo2014";
  const DirectionSet dome = DirectionSet::ubo2014();
  info.dome1_max_dev_deg = -1;
  if (d.num_lights() == dome.size() && d.num_views() == dome.size()) {
    double mx = 0;
    for (const DirectionSet* s : {&d.lights, &d.views})
      for (size_t i = 0; i < dome.size(); ++i) {
        const Vec3 &a = s->dirs[i], &b = dome.dirs[i];
        // atan2(|a x b|, a . b): well conditioned near 0, unlike acos of the dot product.
        const double cx = double(a.y) * b.z - double(a.z) * b.y, cy = double(a.z) * b.x - double(a.x) * b.z,
                     cz = double(a.x) * b.y - double(a.y) * b.x;
        const double dot = double(a.x) * b.x + double(a.y) * b.y + double(a.z) * b.z;
        mx = std::fmax(mx, std::atan2(std::sqrt(cx * cx + cy * cy + cz * cz), dot) * 180.0 / M_PI);
      }
    info.dome1_max_dev_deg = mx;
  }
  Status s = d.validate();
  if (!s.ok()) return src.corrupt(s.message());
  return {};
}

}  // namespace bonn
}  // namespace btfc
