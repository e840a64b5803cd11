// BSVTF reader; the format is pinned in bsvtf.h. Everything in the header and directory is
// checked against the file length and the geometry before anything is allocated by a count
// read from the file.
#include <Imath/half.h>
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>

#include <cerrno>
#include <cmath>
#include <cstring>

#include "formats/bsvtf/bsvtf.h"

#include "core/limits.h"
#include "core/params.h"

namespace btfc {
namespace {

using namespace bsvtf;

// Little-endian cursor over a byte buffer the caller has already sized.
struct In {
  const uint8_t* p;
  size_t pos = 0;
  uint64_t u(int n) {
    uint64_t v = 0;
    for (int i = 0; i < n; ++i) v |= uint64_t(p[pos + size_t(i)]) << (8 * i);
    pos += size_t(n);
    return v;
  }
  uint32_t u32() { return uint32_t(u(4)); }
  float f32() {
    const uint32_t b = u32();
    float f;
    std::memcpy(&f, &b, 4);
    return f;
  }
};

Status read_at(int fd, uint64_t offset, void* dst, size_t n, const std::string& path, const char* what) {
  auto* d = static_cast<uint8_t*>(dst);
  while (n > 0) {
    const ssize_t k = ::pread(fd, d, n, off_t(offset));
    if (k < 0 && errno == EINTR) continue;
    if (k < 0) return io_error(path + ": reading " + what + " failed: " + std::strerror(errno));
    if (k == 0) return corrupt_data(path + ": truncated while reading " + what);
    d += k, n -= size_t(k), offset += uint64_t(k);
  }
  return {};
}

}  // namespace

Result<BsvtfReader> BsvtfReader::open(const std::string& path) {
  BsvtfReader r;
  r.m_path = path;
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return io_error(path + ": cannot open: " + std::strerror(errno));
  r.m_fd = std::shared_ptr<int>(new int(fd), [](int* p) {
    ::close(*p);
    delete p;
  });
  struct stat st {};
  if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) return io_error(path + ": not a regular file");
  const uint64_t size = uint64_t(st.st_size);
  r.m_file_bytes = size;
  auto bad = [&](const std::string& m) { return corrupt_data(path + ": " + m); };
  if (size < 80) return bad("truncated: " + std::to_string(size) + " bytes, a BSVTF header needs more than 80");
  uint8_t fixed[80];
  BTFC_RETURN_IF_ERROR(read_at(fd, 0, fixed, 80, path, "the header"));
  if (std::memcmp(fixed, "BSVTF\r\n\x1a", 8) != 0) return bad("not a BSVTF file (wrong magic)");
  In in{fixed};
  in.pos = 8;
  const uint32_t major = uint32_t(in.u(2)), minor = uint32_t(in.u(2));
  if (major != 1)
    return unsupported(path + ": BSVTF version " + std::to_string(major) + "." + std::to_string(minor) + " is not readable by this btfc (1.x)");
  const uint32_t header_bytes = in.u32(), width = in.u32(), height = in.u32(), tile = in.u32(), border = in.u32(), comps = in.u32();
  const uint32_t levels = in.u32(), quality = in.u32(), color = in.u32(), channels = in.u32(), nl = in.u32(), nv = in.u32();
  const uint32_t nb = in.u32();
  const uint64_t num_entries = in.u(8), data_bytes = in.u(8);
  if (width > (1u << 20) || height > (1u << 20) || tile > 1024 || border > 64 || comps > 4)
    return bad("header: texture or tile size out of range");
  auto geo = Geometry::make(int(width), int(height), int(tile), int(border), int(comps));
  if (!geo.ok()) return bad("header: " + geo.status().message());
  r.m_geo = *geo;
  if (levels != uint32_t(r.m_geo.levels))
    return bad("header: " + std::to_string(levels) + " levels, but a " + std::to_string(width) + " x " + std::to_string(height) +
               " texture in " + std::to_string(tile) + "-texel tiles has " + std::to_string(r.m_geo.levels));
  if (quality < 1 || quality > 100) return bad("header: quality " + std::to_string(quality) + " outside [1, 100]");
  if (color != 0 && color != 11 && color != 13) return bad("header: unknown colour model " + std::to_string(color));
  const bool dfmf = color != 0, own_offset = color == 13;  // 13: dfmf with its luminance offset stored (bsvtf.h)
  if (own_offset && minor < 1) return bad("header: colour model 13 needs version 1.1, the file says 1." + std::to_string(minor));
  if (channels < 1 || channels > 16 || (dfmf && channels != 3)) return bad("header: " + std::to_string(channels) + " colour channels");
  if (nb != (color == 0 ? 1u : 3u)) return bad("header: " + std::to_string(nb) + " blocks for colour model " + std::to_string(color));
  if (nl < 1 || nv < 1 || nl > (1u << 20) || nv > (1u << 20)) return bad("header: direction counts out of range");
  const uint64_t expect_header = 80 + 12 * (uint64_t(nl) + nv) + 280 * uint64_t(nb) + (own_offset ? 4 : 0) + 8;
  if (header_bytes != expect_header)
    return bad("header: header_bytes " + std::to_string(header_bytes) + " disagrees with its contents (" + std::to_string(expect_header) + ")");
  if (header_bytes > size) return bad("truncated: header of " + std::to_string(header_bytes) + " bytes, file of " + std::to_string(size));
  if (num_entries > (size - header_bytes) / 40 || data_bytes > size)
    return bad("truncated: directory of " + std::to_string(num_entries) + " entries does not fit in " + std::to_string(size) + " bytes");
  if (header_bytes + 40 * num_entries + data_bytes != size)
    return bad("file is " + std::to_string(size) + " bytes, header + directory + data say " +
               std::to_string(header_bytes + 40 * num_entries + data_bytes) + (size < header_bytes + 40 * num_entries + data_bytes ? " (truncated)" : ""));

  std::vector<uint8_t> head(header_bytes);
  BTFC_RETURN_IF_ERROR(read_at(fd, 0, head.data(), head.size(), path, "the header"));
  if (uint32_t(crc32(0, head.data(), uInt(header_bytes - 4))) != In{head.data(), header_bytes - 4}.u32())
    return bad("header checksum mismatch");
  in = In{head.data(), 80};
  r.m_quality = int(quality), r.m_color = int(color), r.m_channels = int(channels);
  for (auto [set, n] : {std::pair{&r.m_lights, nl}, std::pair{&r.m_views, nv}}) {
    for (uint32_t i = 0; i < n; ++i) {
      Vec3 d;
      d.x = in.f32(), d.y = in.f32(), d.z = in.f32();
      const double len = std::sqrt(double(d.x) * d.x + double(d.y) * d.y + double(d.z) * d.z);
      if (!std::isfinite(len) || std::abs(len - 1) > 1e-3) return bad("header: direction " + std::to_string(i) + " is not a unit vector");
      set->dirs.push_back(d);
    }
    set->identify();
  }
  const char* names[3] = {dfmf ? "y" : "rgb", "u", "v"};
  for (uint32_t b = 0; b < nb; ++b) {
    BsvtfBlock blk;
    char name[9] = {};
    std::memcpy(name, head.data() + in.pos, 8);
    in.pos += 8;
    blk.name = name;
    blk.rows = in.u32(), blk.components = in.u32(), blk.groups = in.u32(), blk.range = in.f32();
    for (float& s : blk.steps) s = in.f32();
    const std::string where = "header: block " + std::to_string(b) + " ('" + blk.name + "')";
    if (blk.name != names[b]) return bad(where + ": expected block '" + names[b] + "'");
    if (blk.rows != (dfmf ? 1u : channels) * uint64_t(nl) * nv) return bad(where + ": " + std::to_string(blk.rows) + " rows disagree with the directions");
    if (blk.components < 1 || blk.components > 65536 || blk.groups != (blk.components + comps - 1) / comps)
      return bad(where + ": " + std::to_string(blk.components) + " components in " + std::to_string(blk.groups) + " groups");
    if (!(std::isfinite(blk.range) && blk.range > 0)) return bad(where + ": range is not a positive number");
    for (float s : blk.steps)
      if (!(std::isfinite(s) && s > 0)) return bad(where + ": a quantisation step is not a positive number");
    for (uint32_t gi = 0; gi < blk.groups; ++gi) r.m_texture_block.push_back(int(b)), r.m_texture_group.push_back(int(gi));
    r.m_blocks.push_back(blk);
  }
  if (own_offset) {
    r.m_offset = in.f32();
    if (!(std::isfinite(r.m_offset) && r.m_offset > 0))
      return bad("header: luminance offset " + real_string(r.m_offset) + " is not a positive number");
  }
  const uint32_t dir_crc = in.u32();
  const size_t T = r.textures();
  if (num_entries != 2 * T + T * (r.m_geo.tiles_total() - 1))
    return bad("directory has " + std::to_string(num_entries) + " entries, the geometry needs " + std::to_string(2 * T + T * (r.m_geo.tiles_total() - 1)));

  std::vector<uint8_t> dir(40 * num_entries);
  BTFC_RETURN_IF_ERROR(read_at(fd, header_bytes, dir.data(), dir.size(), path, "the directory"));
  if (uint32_t(crc32(0, dir.data(), uInt(dir.size()))) != dir_crc) return bad("directory checksum mismatch");
  r.m_entries.resize(num_entries);
  r.m_header_bytes = header_bytes + dir.size();
  uint64_t offset = r.m_header_bytes;
  auto expect = [&](size_t e, uint8_t kind, size_t t, int l, int tx, int ty) -> Status {
    In d{dir.data(), 40 * e};
    BsvtfEntry& x = r.m_entries[e];
    x.kind = uint8_t(d.u(1)), x.level = uint8_t(d.u(1)), x.block = uint16_t(d.u(2)), x.group = d.u32(), x.tx = d.u32(), x.ty = d.u32();
    x.offset = d.u(8), x.stored = d.u32(), x.raw = d.u32(), x.weight = d.f32(), x.crc = d.u32();
    const std::string where = "directory entry " + std::to_string(e) + ": ";
    if (x.kind != kind || x.level != l || x.block != r.m_texture_block[t] || x.group != uint32_t(r.m_texture_group[t]) ||
        x.tx != uint32_t(tx) || x.ty != uint32_t(ty))
      return bad(where + "out of order (expected " + (kind == BsvtfEntry::packet ? "packet" : "tile") + " of texture " + std::to_string(t) +
                 " level " + std::to_string(l) + " (" + std::to_string(tx) + ", " + std::to_string(ty) + "))");
    if (x.offset != offset || x.stored > size - offset) return bad(where + "offset / size outside the data");
    const uint64_t raw_min = kind == BsvtfEntry::packet ? uint64_t(r.m_blocks[x.block].rows) * comps * 2 : r.m_geo.tile_floats();
    const uint64_t raw_max = kind == BsvtfEntry::packet ? raw_min : r.m_geo.max_raw_tile_bytes();
    if (x.raw < raw_min || x.raw > raw_max) return bad(where + "raw size " + std::to_string(x.raw) + " impossible for its kind");
    // zlib inflates at most 1032:1, so the stored bytes bound what a payload decodes to, and with
    // them everything decoding sizes from the geometry: the file must hold its tiles.
    if (uint64_t(x.raw) > uint64_t(x.stored) * 1032)
      return bad(where + "raw size " + std::to_string(x.raw) + " cannot inflate from " + std::to_string(x.stored) + " stored bytes (deflate: at most 1032:1)");
    if (!(std::isfinite(x.weight) && x.weight >= 0)) return bad(where + "weight is not a non-negative number");
    offset += x.stored;
    return {};
  };
  for (size_t t = 0; t < T; ++t) {
    BTFC_RETURN_IF_ERROR(expect(bsvtf_packet_entry(t), BsvtfEntry::packet, t, 0, 0, 0));
    BTFC_RETURN_IF_ERROR(expect(bsvtf_tile_entry(r.m_geo, T, t, 0, 0, 0), BsvtfEntry::tile, t, 0, 0, 0));
  }
  for (int l = 1; l < r.m_geo.levels; ++l)
    for (size_t t = 0; t < T; ++t)
      for (int ty = 0; ty < r.m_geo.tiles_y(l); ++ty)
        for (int tx = 0; tx < r.m_geo.tiles_x(l); ++tx)
          BTFC_RETURN_IF_ERROR(expect(bsvtf_tile_entry(r.m_geo, T, t, l, tx, ty), BsvtfEntry::tile, t, l, tx, ty));
  if (offset != size) return bad("payload sizes add up to " + std::to_string(offset - r.m_header_bytes) + " bytes, data_bytes says " + std::to_string(data_bytes));
  return r;
}

Result<std::vector<uint8_t>> BsvtfReader::payload(size_t e) const {
  const BsvtfEntry& x = m_entries[e];
  const std::string what = "entry " + std::to_string(e);
  std::vector<uint8_t> stored(x.stored);
  BTFC_RETURN_IF_ERROR(read_at(*m_fd, x.offset, stored.data(), stored.size(), m_path, what.c_str()));
  if (uint32_t(crc32(0, stored.data(), uInt(stored.size()))) != x.crc) return corrupt_data(m_path + ": " + what + ": checksum mismatch");
  std::vector<uint8_t> raw;
  Status s = inflate_bytes(stored.data(), stored.size(), x.raw, raw);
  if (!s.ok()) return s.with_context(m_path + ": " + what);
  return raw;
}

Result<std::vector<float>> BsvtfReader::read_packet(size_t t) const {
  if (t >= textures()) return invalid_argument(m_path + ": no virtual texture " + std::to_string(t));
  BTFC_ASSIGN_OR_RETURN(std::vector<uint8_t> raw, payload(bsvtf_packet_entry(t)));
  std::vector<float> out(raw.size() / 2);
  for (size_t i = 0; i < out.size(); ++i) out[i] = float(Imath::half(Imath::half::FromBits, uint16_t(raw[2 * i] | (raw[2 * i + 1] << 8))));
  return out;
}

Status BsvtfReader::read_tile(size_t t, int level, int tx, int ty, const float* parent, float* out) const {
  if (t >= textures() || level < 0 || level >= m_geo.levels || tx < 0 || ty < 0 || tx >= m_geo.tiles_x(level) || ty >= m_geo.tiles_y(level))
    return invalid_argument(m_path + ": no tile (" + std::to_string(t) + ", level " + std::to_string(level) + ", " + std::to_string(tx) + ", " +
                            std::to_string(ty) + ")");
  const size_t e = bsvtf_tile_entry(m_geo, textures(), t, level, tx, ty);
  BTFC_ASSIGN_OR_RETURN(std::vector<uint8_t> raw, payload(e));
  const size_t tf = m_geo.tile_floats();
  std::vector<float> res(tf);
  Status s = decode_residual(m_geo, raw.data(), raw.size(), m_blocks[size_t(m_texture_block[t])].steps.data(), res.data());
  if (!s.ok()) return s.with_context(m_path + ": entry " + std::to_string(e));
  if (level == 0) {
    std::copy(res.begin(), res.end(), out);
    return {};
  }
  predict_from_parent(m_geo, level, tx, ty, parent, out);
  for (size_t i = 0; i < tf; ++i) out[i] += res[i];
  return {};
}

Result<std::vector<std::vector<float>>> BsvtfReader::decode_texture(size_t t) const {
  if (t >= textures()) return invalid_argument(m_path + ": no virtual texture " + std::to_string(t));
  const size_t tf = m_geo.tile_floats();
  std::vector<std::vector<float>> levels(size_t(m_geo.levels));
  for (int l = 0; l < m_geo.levels; ++l) {
    const size_t n = m_geo.tiles_in_level(l);
    const int txn = m_geo.tiles_x(l);
    BTFC_RETURN_IF_ERROR(check_memory(n * tf * sizeof(float), m_path + ": level " + std::to_string(l) + " of texture " + std::to_string(t)));
    levels[size_t(l)].assign(n * tf, 0.0f);
    std::vector<Status> st(n);
#pragma omp parallel for schedule(dynamic)
    for (size_t i = 0; i < n; ++i) {
      const int tx = int(i % size_t(txn)), ty = int(i / size_t(txn));
      const float* parent = l == 0 ? nullptr : &levels[size_t(l) - 1][(size_t(ty / 2) * size_t(m_geo.tiles_x(l - 1)) + size_t(tx / 2)) * tf];
      st[i] = read_tile(t, l, tx, ty, parent, &levels[size_t(l)][i * tf]);
    }
    for (const Status& s : st) BTFC_RETURN_IF_ERROR(s);
  }
  return levels;
}

Result<std::vector<float>> BsvtfReader::decode_eigen_textures(int b) const {
  if (b < 0 || size_t(b) >= m_blocks.size()) return invalid_argument(m_path + ": no block " + std::to_string(b));
  const Geometry& g = m_geo;
  const size_t C = m_blocks[size_t(b)].components, tf = g.tile_floats();
  const int L = g.finest(), d = g.dim(), T = g.tile, B = g.border;
  BTFC_RETURN_IF_ERROR(check_memory(size_t(g.width) * size_t(g.height) * C * sizeof(float), m_path + ": eigen-textures of block " + std::to_string(b)));
  std::vector<float> out(size_t(g.width) * size_t(g.height) * C);
  for (size_t t = 0; t < textures(); ++t) {
    if (m_texture_block[t] != b) continue;
    BTFC_ASSIGN_OR_RETURN(auto levels, decode_texture(t));
    const std::vector<float>& fin = levels[size_t(L)];
    for (int k = 0; k < g.comps; ++k) {
      const size_t c = size_t(m_texture_group[t]) * size_t(g.comps) + size_t(k);
      if (c >= C) break;
      for (int y = 0; y < g.height; ++y)
        for (int x = 0; x < g.width; ++x) {
          const size_t tile = size_t(y / T) * size_t(g.tiles_x(L)) + size_t(x / T);
          out[(size_t(y) * size_t(g.width) + size_t(x)) * C + c] = fin[tile * tf + (size_t(k) * d + size_t(B + y % T)) * d + size_t(B + x % T)];
        }
    }
  }
  return out;
}

Result<std::vector<float>> BsvtfReader::decode_eigen_abrdfs(int b) const {
  if (b < 0 || size_t(b) >= m_blocks.size()) return invalid_argument(m_path + ": no block " + std::to_string(b));
  const size_t C = m_blocks[size_t(b)].components, rows = m_blocks[size_t(b)].rows, K = size_t(m_geo.comps);
  std::vector<float> out(rows * C);
  for (size_t t = 0; t < textures(); ++t) {
    if (m_texture_block[t] != b) continue;
    BTFC_ASSIGN_OR_RETURN(std::vector<float> p, read_packet(t));
    for (size_t r = 0; r < rows; ++r)
      for (size_t k = 0; k < K; ++k) {
        const size_t c = size_t(m_texture_group[t]) * K + k;
        if (c < C) out[r * C + c] = p[r * K + k];
      }
  }
  return out;
}

}  // namespace btfc
