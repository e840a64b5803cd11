// BSVTF writer; the format and the method are described in bsvtf.h and bsvtf_tile.h.
#include <Imath/half.h>
#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>

#include "formats/bsvtf/bsvtf.h"
#include "core/dct.h"
#include "codecs/fmf/fmf.h"
#include "core/params.h"

namespace btfc {

size_t bsvtf_packet_entry(size_t texture) { return 2 * texture; }

size_t bsvtf_tile_entry(const bsvtf::Geometry& g, size_t textures, size_t texture, int level, int tx, int ty) {
  if (level == 0) return 2 * texture + 1;
  size_t base = 2 * textures;
  for (int l = 1; l < level; ++l) base += textures * g.tiles_in_level(l);
  return base + texture * g.tiles_in_level(level) + size_t(ty) * size_t(g.tiles_x(level)) + size_t(tx);
}

namespace {

using namespace bsvtf;
using Clock = std::chrono::steady_clock;

// Little-endian byte sink.
struct Out {
  std::vector<uint8_t> b;
  void bytes(const void* p, size_t n) { b.insert(b.end(), static_cast<const uint8_t*>(p), static_cast<const uint8_t*>(p) + n); }
  void u8(uint8_t v) { b.push_back(v); }
  void u16(uint16_t v) { for (int i = 0; i < 2; ++i) b.push_back(uint8_t(v >> (8 * i))); }
  void u32(uint32_t v) { for (int i = 0; i < 4; ++i) b.push_back(uint8_t(v >> (8 * i))); }
  void u64(uint64_t v) { for (int i = 0; i < 8; ++i) b.push_back(uint8_t(v >> (8 * i))); }
  void f32(float v) {
    uint32_t u;
    std::memcpy(&u, &v, 4);
    u32(u);
  }
};

struct Payload {
  std::vector<uint8_t> stored;
  uint32_t raw = 0;
  float weight = 0;
};

// Error sums of one block at the finest level.
struct ErrSums {
  double sse = 0, ref = 0, max_abs = 0;
};

Status finite_check(const float* p, size_t n, const std::string& what) {
  for (size_t i = 0; i < n; ++i)
    if (!std::isfinite(p[i])) return invalid_argument(what + " has a non-finite value at index " + std::to_string(i));
  return {};
}

// Encodes every tile of one virtual texture (K planes of the block's eigen-textures) into
// `payloads` (directory positions) and adds the finest level's error to `err`.
Status encode_texture(const Geometry& g, const FmfBlockView& b, int group, size_t textures, size_t t, const float* steps,
                      std::vector<Payload>& payloads, ErrSums& err) {
  const int K = g.comps, L = g.finest();
  const size_t texels = size_t(g.width) * size_t(g.height), tf = g.tile_floats();
  std::vector<std::vector<float>> level(size_t(L) + 1);
  level[size_t(L)].assign(size_t(K) * texels, 0.0f);
  for (int k = 0; k < K; ++k) {
    const int c = group * K + k;
    if (c >= b.C) continue;
    for (size_t i = 0; i < texels; ++i) level[size_t(L)][size_t(k) * texels + i] = b.SxV[i * size_t(b.C) + size_t(c)];
  }
  for (int l = L; l > 0; --l) level[size_t(l) - 1] = downsample(level[size_t(l)], g.level_width(l), g.level_height(l), K);

  std::vector<float> prev_true, prev_dec;  // the previous level's tiles: original and decoded
  bool failed = false;
  for (int l = 0; l <= L; ++l) {
    const int tx_n = g.tiles_x(l), lw = g.level_width(l), lh = g.level_height(l);
    const size_t n = g.tiles_in_level(l);
    std::vector<float> cur_true(n * tf), cur_dec(n * tf);
#pragma omp parallel for schedule(dynamic)
    for (size_t i = 0; i < n; ++i) {
      const int tx = int(i % size_t(tx_n)), ty = int(i / size_t(tx_n));
      float* tru = &cur_true[i * tf];
      float* dec = &cur_dec[i * tf];
      extract_tile(g, level[size_t(l)].data(), lw, lh, tx, ty, tru);
      std::vector<float> pred(tf, 0.0f), res(tf), dres(tf);
      double w;
      if (l == 0) {
        w = tile_weight(g, tru, nullptr);
      } else {
        const size_t parent = size_t(ty / 2) * size_t(g.tiles_x(l - 1)) + size_t(tx / 2);
        predict_from_parent(g, l, tx, ty, &prev_true[parent * tf], pred.data());
        w = tile_weight(g, tru, pred.data());  // eq. 8: against the original parent
        predict_from_parent(g, l, tx, ty, &prev_dec[parent * tf], pred.data());
      }
      for (size_t j = 0; j < tf; ++j) res[j] = tru[j] - pred[j];
      std::vector<uint8_t> raw = encode_residual(g, res.data(), steps, dres.data());
      for (size_t j = 0; j < tf; ++j) dec[j] = pred[j] + dres[j];
      Payload& p = payloads[bsvtf_tile_entry(g, textures, t, l, tx, ty)];
      p.raw = uint32_t(raw.size());
      p.stored = deflate_bytes(raw);
      p.weight = float(w);
      if (p.stored.empty()) {
#pragma omp atomic write
        failed = true;
      }
    }
    if (failed) return codec_error("zlib could not deflate a tile (out of memory?)");
    prev_true.swap(cur_true);
    prev_dec.swap(cur_dec);
  }
  // Finest level: the decoded interiors against the model's eigen-textures (real components only).
  const int d = g.dim(), T = g.tile, B = g.border, tx_n = g.tiles_x(L);
  for (int k = 0; k < K && group * K + k < b.C; ++k)
    for (int y = 0; y < g.height; ++y)
      for (int x = 0; x < g.width; ++x) {
        const size_t tile = size_t(y / T) * size_t(tx_n) + size_t(x / T);
        const float v = prev_dec[tile * tf + (size_t(k) * d + size_t(B + y % T)) * d + size_t(B + x % T)];
        const double ref = level[size_t(L)][size_t(k) * texels + size_t(y) * size_t(g.width) + size_t(x)];
        const double e = double(v) - ref;
        err.sse += e * e, err.ref += ref * ref, err.max_abs = std::max(err.max_abs, std::abs(e));
      }
  return {};
}

Payload encode_packet(const FmfBlockView& b, int group, int K) {
  std::vector<uint8_t> raw(b.rows * size_t(K) * 2, 0);
  for (size_t r = 0; r < b.rows; ++r)
    for (int k = 0; k < K; ++k) {
      const int c = group * K + k;
      const uint16_t h = c < b.C ? Imath::half(b.U[r * size_t(b.C) + size_t(c)]).bits() : 0;
      raw[(r * size_t(K) + size_t(k)) * 2] = uint8_t(h), raw[(r * size_t(K) + size_t(k)) * 2 + 1] = uint8_t(h >> 8);
    }
  Payload p;
  p.raw = uint32_t(raw.size());
  p.stored = deflate_bytes(raw);
  return p;
}

Status write_file(const std::string& path, const std::vector<uint8_t>& head, const std::vector<uint8_t>& dir, const std::vector<Payload>& payloads) {
  const std::string tmp = path + ".tmp-" + std::to_string(::getpid());
  FILE* f = std::fopen(tmp.c_str(), "wb");
  if (!f) return io_error(path + ": cannot create temporary file '" + tmp + "': " + std::strerror(errno));
  bool ok = std::fwrite(head.data(), 1, head.size(), f) == head.size() && std::fwrite(dir.data(), 1, dir.size(), f) == dir.size();
  for (size_t i = 0; ok && i < payloads.size(); ++i)
    ok = std::fwrite(payloads[i].stored.data(), 1, payloads[i].stored.size(), f) == payloads[i].stored.size();
  // Flush and sync before the rename so a crash never leaves a short file under `path`.
  ok = ok && std::fflush(f) == 0 && fsync(fileno(f)) == 0;
  std::string err = ok ? "" : std::strerror(errno);
  if (std::fclose(f) != 0 && ok) ok = false, err = std::strerror(errno);
  if (!ok) {
    std::remove(tmp.c_str());
    return io_error(path + ": write to '" + tmp + "' failed: " + err);
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    err = std::strerror(errno);
    std::remove(tmp.c_str());
    return io_error(path + ": cannot rename '" + tmp + "' into place: " + err);
  }
  return {};
}

}  // namespace

int bsvtf_color_model(const FmfFactorsView& f) {
  if (f.bonn_color_model != (f.per_channel ? 11 : 0)) return -1;
  // A dfmf model with Bonn's offset is colour model 11 in a version 1.0 file, as before; with any
  // other offset (btfc's default picks one from the data) colour model 13, which stores it: a
  // 1.1 file that a 1.0 reader refuses by its colour model (bsvtf.h).
  return f.per_channel ? (f.drr_eps == 1e-5f ? 11 : 13) : 0;
}

Status write_bsvtf(const Model& model, const BsvtfOptions& opt, const std::string& path, BsvtfReport* report) {
  const auto t0 = Clock::now();
  BTFC_ASSIGN_OR_RETURN(FmfFactorsView f, fmf_factors(model));
  const BtfDesc& desc = model.desc();
  const int color = bsvtf_color_model(f);
  if (color < 0)
    return unsupported(path + ": the fmf model uses Bonn colour model " + std::to_string(f.bonn_color_model) +
                       "; BSVTF stores FMF rgb (model 0) and DFMF (model 11) models only");
  const bool own_offset = color == 13;
  if (own_offset && !(std::isfinite(f.drr_eps) && f.drr_eps > 0))
    return invalid_argument(path + ": the dfmf model's luminance offset " + real_string(f.drr_eps) + " is not a positive number");
  if (opt.quality < 1 || opt.quality > 100) return invalid_argument(path + ": quality " + std::to_string(opt.quality) + " outside [1, 100]");
  auto geo = Geometry::make(desc.width, desc.height, opt.tile, opt.border, 4);
  if (!geo.ok()) return geo.status().with_context(path);
  const Geometry& g = *geo;

  // Per block: value range and quantisation steps; the virtual textures (block, group).
  std::vector<std::array<float, 64>> steps;
  std::vector<float> ranges;
  std::vector<std::pair<int, int>> textures;
  for (size_t bi = 0; bi < f.blocks.size(); ++bi) {
    const FmfBlockView& b = f.blocks[bi];
    BTFC_RETURN_IF_ERROR(finite_check(b.SxV, b.texels * size_t(b.C), path + ": block " + b.name + " eigen-textures"));
    BTFC_RETURN_IF_ERROR(finite_check(b.U, b.rows * size_t(b.C), path + ": block " + b.name + " eigen-ABRDFs"));
    const auto [lo, hi] = std::minmax_element(b.SxV, b.SxV + b.texels * size_t(b.C));
    // A constant block has no range: its magnitude (or 1 for zeros) sets the steps instead.
    float range = *hi - *lo;
    if (!(range > 0)) range = std::max(std::abs(*hi), std::abs(*lo)) > 0 ? std::max(std::abs(*hi), std::abs(*lo)) : 1.0f;
    ranges.push_back(range);
    steps.push_back(dct::quant_steps(opt.quality, range));
    for (int gi = 0; gi < (b.C + g.comps - 1) / g.comps; ++gi) textures.emplace_back(int(bi), gi);
  }

  std::vector<Payload> payloads(2 * textures.size() + textures.size() * (g.tiles_total() - 1));
  std::vector<ErrSums> err(f.blocks.size());
  for (size_t t = 0; t < textures.size(); ++t) {
    const auto [bi, gi] = textures[t];
    payloads[bsvtf_packet_entry(t)] = encode_packet(f.blocks[size_t(bi)], gi, g.comps);
    if (payloads[bsvtf_packet_entry(t)].stored.empty()) return codec_error(path + ": zlib could not deflate an ABRDF packet");
    Status s = encode_texture(g, f.blocks[size_t(bi)], gi, textures.size(), t, steps[size_t(bi)].data(), payloads, err[size_t(bi)]);
    if (!s.ok()) return s.with_context(path);
  }

  // Header, then the directory with absolute offsets.
  const uint64_t header_bytes =
      80 + 12 * uint64_t(desc.num_lights() + desc.num_views()) + 280 * uint64_t(f.blocks.size()) + (own_offset ? 4 : 0) + 8;
  uint64_t offset = header_bytes + 40 * uint64_t(payloads.size()), data_bytes = 0;
  Out dir;
  for (size_t e = 0; e < payloads.size(); ++e) {
    // Recover (kind, level, texture, tx, ty) of entry e from the pinned order.
    uint8_t kind = BsvtfEntry::tile, level = 0;
    size_t t = 0;
    uint32_t tx = 0, ty = 0;
    if (e < 2 * textures.size()) {
      t = e / 2, kind = e % 2 == 0 ? BsvtfEntry::packet : BsvtfEntry::tile;
    } else {
      size_t r = e - 2 * textures.size();
      int l = 1;
      while (r >= textures.size() * g.tiles_in_level(l)) r -= textures.size() * g.tiles_in_level(l), ++l;
      level = uint8_t(l), t = r / g.tiles_in_level(l);
      const size_t i = r % g.tiles_in_level(l);
      tx = uint32_t(i % size_t(g.tiles_x(l))), ty = uint32_t(i / size_t(g.tiles_x(l)));
    }
    const Payload& p = payloads[e];
    if (p.stored.size() > UINT32_MAX) return codec_error(path + ": a payload exceeds 4 GiB");
    dir.u8(kind), dir.u8(level), dir.u16(uint16_t(textures[t].first)), dir.u32(uint32_t(textures[t].second));
    dir.u32(tx), dir.u32(ty), dir.u64(offset), dir.u32(uint32_t(p.stored.size())), dir.u32(p.raw), dir.f32(p.weight);
    dir.u32(uint32_t(crc32(0, p.stored.data(), uInt(p.stored.size()))));
    offset += p.stored.size(), data_bytes += p.stored.size();
  }
  Out h;
  h.bytes("BSVTF\r\n\x1a", 8);
  h.u16(1), h.u16(own_offset ? 1 : 0), h.u32(uint32_t(header_bytes)), h.u32(uint32_t(g.width)), h.u32(uint32_t(g.height));
  h.u32(uint32_t(g.tile)), h.u32(uint32_t(g.border)), h.u32(uint32_t(g.comps)), h.u32(uint32_t(g.levels)), h.u32(uint32_t(opt.quality));
  h.u32(uint32_t(color)), h.u32(uint32_t(desc.channels)), h.u32(uint32_t(desc.num_lights())), h.u32(uint32_t(desc.num_views()));
  h.u32(uint32_t(f.blocks.size())), h.u64(payloads.size()), h.u64(data_bytes);
  for (const DirectionSet* s : {&desc.lights, &desc.views})
    for (const Vec3& d : s->dirs) h.f32(d.x), h.f32(d.y), h.f32(d.z);
  for (size_t bi = 0; bi < f.blocks.size(); ++bi) {
    char name[8] = {};
    std::strncpy(name, f.blocks[bi].name.c_str(), 7);
    h.bytes(name, 8);
    h.u32(uint32_t(f.blocks[bi].rows)), h.u32(uint32_t(f.blocks[bi].C)), h.u32(uint32_t((f.blocks[bi].C + g.comps - 1) / g.comps));
    h.f32(ranges[bi]);
    for (float s : steps[bi]) h.f32(s);
  }
  if (own_offset) h.f32(f.drr_eps);
  h.u32(uint32_t(crc32(0, dir.b.data(), uInt(dir.b.size()))));
  h.u32(uint32_t(crc32(0, h.b.data(), uInt(h.b.size()))));
  if (h.b.size() != header_bytes) return codec_error(path + ": internal error: header size mismatch");
  BTFC_RETURN_IF_ERROR(write_file(path, h.b, dir.b, payloads));

  if (report) {
    BsvtfReport r;
    r.textures = textures.size(), r.tiles = textures.size() * g.tiles_total(), r.levels = g.levels;
    r.header_bytes = header_bytes + dir.b.size(), r.file_bytes = r.header_bytes + data_bytes;
    for (size_t t = 0; t < textures.size(); ++t) r.packet_bytes += payloads[bsvtf_packet_entry(t)].stored.size();
    r.tile_bytes = data_bytes - r.packet_bytes;
    r.tile_raw_half_bytes = uint64_t(r.tiles) * g.tile_floats() * 2;
    double norm_sse = 0, n_all = 0, sse = 0, ref = 0;
    for (size_t bi = 0; bi < f.blocks.size(); ++bi) {
      const double n = double(f.blocks[bi].texels) * f.blocks[bi].C, rr = double(ranges[bi]) * ranges[bi];
      r.eigen_f32_bytes += uint64_t(n) * 4, r.eigen_f16_bytes += uint64_t(n) * 2;
      r.block_psnr.emplace_back(f.blocks[bi].name, err[bi].sse > 0 ? 10 * std::log10(rr * n / err[bi].sse) : INFINITY);
      norm_sse += err[bi].sse / rr, n_all += n, sse += err[bi].sse, ref += err[bi].ref;
      r.max_abs = std::max(r.max_abs, err[bi].max_abs);
    }
    r.psnr = norm_sse > 0 ? 10 * std::log10(n_all / norm_sse) : INFINITY;
    r.rel_l2 = ref > 0 ? std::sqrt(sse / ref) : std::sqrt(sse);
    r.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
    *report = std::move(r);
  }
  return {};
}

}  // namespace btfc
