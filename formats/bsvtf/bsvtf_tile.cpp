// BSVTF tiles: geometry, pyramid, prediction, residual codec; see bsvtf_tile.h.
#include "formats/bsvtf/bsvtf_tile.h"

#include <zlib.h>

#include <algorithm>
#include <cmath>
#include <string>

#include "core/dct.h"

namespace btfc::bsvtf {

int Geometry::level_width(int l) const {
  const int shift = finest() - l;
  return int((int64_t(width) + (int64_t(1) << shift) - 1) >> shift);
}
int Geometry::level_height(int l) const {
  const int shift = finest() - l;
  return int((int64_t(height) + (int64_t(1) << shift) - 1) >> shift);
}

size_t Geometry::tiles_total() const {
  size_t n = 0;
  for (int l = 0; l < levels; ++l) n += tiles_in_level(l);
  return n;
}

Result<Geometry> Geometry::make(int width, int height, int tile, int border, int comps) {
  if (width < 1 || height < 1 || width > (1 << 20) || height > (1 << 20))
    return invalid_argument("texture size " + std::to_string(width) + " x " + std::to_string(height) + " outside [1, 2^20]");
  if (tile < 8 || tile > 1024) return invalid_argument("tile size " + std::to_string(tile) + " outside [8, 1024]");
  if (border < 2 || border > 64) return invalid_argument("tile border " + std::to_string(border) + " outside [2, 64]");
  if ((tile + 2 * border) % 8 != 0)
    return invalid_argument("tile size + 2 x border = " + std::to_string(tile + 2 * border) + " is not a multiple of 8 (8 x 8 DCT blocks)");
  if (comps < 1 || comps > 4) return invalid_argument("components per tile " + std::to_string(comps) + " outside [1, 4]");
  Geometry g;
  g.width = width, g.height = height, g.tile = tile, g.border = border, g.comps = comps;
  int L = 0;
  while ((std::max(width, height) + (1 << L) - 1) >> L > tile) ++L;
  g.levels = L + 1;
  return g;
}

std::vector<float> downsample(const std::vector<float>& img, int w, int h, int comps) {
  const int w2 = (w + 1) / 2, h2 = (h + 1) / 2;
  std::vector<float> out(size_t(comps) * size_t(w2) * size_t(h2));
  for (int k = 0; k < comps; ++k) {
    const float* src = img.data() + size_t(k) * size_t(w) * size_t(h);
    float* dst = out.data() + size_t(k) * size_t(w2) * size_t(h2);
    for (int y = 0; y < h2; ++y)
      for (int x = 0; x < w2; ++x) {
        double s = 0;
        int n = 0;
        for (int dy = 0; dy < 2; ++dy)
          for (int dx = 0; dx < 2; ++dx) {
            const int sx = 2 * x + dx, sy = 2 * y + dy;
            if (sx < w && sy < h) s += src[size_t(sy) * size_t(w) + size_t(sx)], ++n;
          }
        dst[size_t(y) * size_t(w2) + size_t(x)] = float(s / n);
      }
  }
  return out;
}

void extract_tile(const Geometry& g, const float* img, int lw, int lh, int tx, int ty, float* tile) {
  const int d = g.dim(), ox = g.tile * tx - g.border, oy = g.tile * ty - g.border;
  for (int k = 0; k < g.comps; ++k) {
    const float* plane = img + size_t(k) * size_t(lw) * size_t(lh);
    for (int y = 0; y < d; ++y) {
      const int sy = std::clamp(oy + y, 0, lh - 1);
      for (int x = 0; x < d; ++x) {
        const int sx = std::clamp(ox + x, 0, lw - 1);
        tile[(size_t(k) * d + y) * d + x] = plane[size_t(sy) * size_t(lw) + size_t(sx)];
      }
    }
  }
}

namespace {

// The two parent taps (local indices, weights) of local child coordinate `x` along one axis.
struct Taps {
  int i0, i1;
  float w0, w1;
};
Taps taps(int local, int origin, int level_size, int parent_origin) {
  const int s = std::clamp(origin + local, 0, level_size - 1), m = s >> 1;
  const int other = (s & 1) ? m + 1 : m - 1;
  return {m - parent_origin, other - parent_origin, 0.75f, 0.25f};
}

}  // namespace

void predict_from_parent(const Geometry& g, int level, int tx, int ty, const float* parent, float* pred) {
  const int d = g.dim(), T = g.tile, B = g.border;
  const int lw = g.level_width(level), lh = g.level_height(level);
  std::vector<Taps> ax(static_cast<size_t>(d)), ay(static_cast<size_t>(d));
  for (int i = 0; i < d; ++i) {
    ax[size_t(i)] = taps(i, T * tx - B, lw, T * (tx / 2) - B);
    ay[size_t(i)] = taps(i, T * ty - B, lh, T * (ty / 2) - B);
  }
  for (int k = 0; k < g.comps; ++k) {
    const float* p = parent + size_t(k) * d * d;
    for (int y = 0; y < d; ++y) {
      const Taps& a = ay[size_t(y)];
      const float* r0 = p + size_t(a.i0) * d;
      const float* r1 = p + size_t(a.i1) * d;
      for (int x = 0; x < d; ++x) {
        const Taps& b = ax[size_t(x)];
        pred[(size_t(k) * d + y) * d + x] = a.w0 * (b.w0 * r0[b.i0] + b.w1 * r0[b.i1]) + a.w1 * (b.w0 * r1[b.i0] + b.w1 * r1[b.i1]);
      }
    }
  }
}

double tile_weight(const Geometry& g, const float* tile, const float* pred) {
  const int d = g.dim(), B = g.border, T = g.tile;
  double s = 0;
  for (int k = 0; k < g.comps; ++k)
    for (int y = B; y < B + T; ++y)
      for (int x = B; x < B + T; ++x) {
        const size_t i = (size_t(k) * d + y) * d + x;
        const double e = double(tile[i]) - (pred ? double(pred[i]) : 0.0);
        s += e * e;
      }
  return s / (double(T) * T);
}

namespace {

void put_varint(std::vector<uint8_t>& out, int32_t q) {
  uint32_t z = (uint32_t(q) << 1) ^ uint32_t(q >> 31);
  while (z >= 0x80) out.push_back(uint8_t(z | 0x80)), z >>= 7;
  out.push_back(uint8_t(z));
}

}  // namespace

std::vector<uint8_t> encode_residual(const Geometry& g, const float* residual, const float* steps, float* decoded) {
  const int d = g.dim(), nb = d / 8, blocks = nb * nb;
  std::vector<int32_t> q(size_t(g.comps) * size_t(blocks) * 64);
  double coef[64];
  for (int k = 0; k < g.comps; ++k)
    for (int b = 0; b < blocks; ++b) {
      const size_t off = (size_t(k) * d + size_t(b / nb) * 8) * d + size_t(b % nb) * 8;
      dct::fdct8x8(residual + off, d, coef);
      int32_t* qb = &q[(size_t(k) * blocks + size_t(b)) * 64];
      for (int i = 0; i < 64; ++i) {
        // Clamped so that absurd inputs cannot overflow int32 (a clamp only matters for data
        // far beyond `range`, which the writer's range already covers).
        const double r = std::clamp(std::nearbyint(coef[i] / double(steps[i])), -1e9, 1e9);
        qb[i] = int32_t(r);
        coef[i] = double(qb[i]) * double(steps[i]);
      }
      dct::idct8x8(coef, decoded + off, d);
    }
  std::vector<uint8_t> raw;
  raw.reserve(q.size());
  for (int k = 0; k < g.comps; ++k)
    for (int z = 0; z < 64; ++z)
      for (int b = 0; b < blocks; ++b) put_varint(raw, q[(size_t(k) * blocks + size_t(b)) * 64 + dct::k_zigzag[size_t(z)]]);
  return raw;
}

Status decode_residual(const Geometry& g, const uint8_t* raw, size_t n, const float* steps, float* residual) {
  const int d = g.dim(), nb = d / 8, blocks = nb * nb;
  std::vector<int32_t> q(size_t(g.comps) * size_t(blocks) * 64);
  size_t pos = 0;
  for (int k = 0; k < g.comps; ++k)
    for (int z = 0; z < 64; ++z)
      for (int b = 0; b < blocks; ++b) {
        uint32_t v = 0;
        for (int shift = 0;; shift += 7) {
          if (pos >= n) return corrupt_data("tile payload ends inside coefficient data (" + std::to_string(n) + " bytes)");
          const uint8_t c = raw[pos++];
          if (shift == 28 && (c & 0xF0)) return corrupt_data("tile payload has a coefficient varint longer than 32 bits");
          v |= uint32_t(c & 0x7F) << shift;
          if (!(c & 0x80)) break;
        }
        q[(size_t(k) * blocks + size_t(b)) * 64 + dct::k_zigzag[size_t(z)]] = int32_t((v >> 1) ^ (0u - (v & 1)));
      }
  if (pos != n) return corrupt_data("tile payload has " + std::to_string(n - pos) + " bytes after its coefficients");
  double coef[64];
  for (int k = 0; k < g.comps; ++k)
    for (int b = 0; b < blocks; ++b) {
      const int32_t* qb = &q[(size_t(k) * blocks + size_t(b)) * 64];
      for (int i = 0; i < 64; ++i) coef[i] = double(qb[i]) * double(steps[i]);
      dct::idct8x8(coef, residual + (size_t(k) * d + size_t(b / nb) * 8) * d + size_t(b % nb) * 8, d);
    }
  return {};
}

std::vector<uint8_t> deflate_bytes(const std::vector<uint8_t>& raw) {
  uLongf n = compressBound(uLong(raw.size()));
  std::vector<uint8_t> out(n);
  if (compress2(out.data(), &n, raw.data(), uLong(raw.size()), 9) != Z_OK) return {};  // only on out-of-memory
  out.resize(n);
  return out;
}

Status inflate_bytes(const uint8_t* data, size_t n, size_t raw_size, std::vector<uint8_t>& out) {
  out.assign(raw_size, 0);
  uLongf got = uLongf(raw_size);
  uLong used = uLong(n);
  const int rc = uncompress2(out.data(), &got, data, &used);
  if (rc == Z_BUF_ERROR && got == raw_size) return corrupt_data("deflate stream inflates to more than the recorded " + std::to_string(raw_size) + " bytes");
  if (rc != Z_OK) return corrupt_data(std::string("deflate stream is damaged (zlib: ") + (rc == Z_DATA_ERROR ? "data error" : rc == Z_BUF_ERROR ? "truncated" : "error") + ")");
  if (got != raw_size) return corrupt_data("deflate stream inflates to " + std::to_string(got) + " bytes, not the recorded " + std::to_string(raw_size));
  if (used != n) return corrupt_data("deflate stream is followed by " + std::to_string(n - used) + " stray bytes");
  return {};
}

}  // namespace btfc::bsvtf
