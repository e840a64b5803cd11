// BSVTF tile geometry, mip pyramid, parent prediction and the tile residual codec: the parts
// the writer (bsvtf_write.cpp), the reader (bsvtf_read.cpp) and the tile-cache simulator share.
// Seed 000 sections 3 and 6; the byte format is pinned in bsvtf.h.
//
// Geometry. A virtual texture is K eigen-textures (planes) of width x height texels. Level
// l = 0 .. L (L = levels - 1) has ceil(width / 2^(L-l)) x ceil(height / 2^(L-l)) texels: L is
// the full resolution, level 0 the first that fits in one tile (the paper's T_0 = {T_(0,0)}).
// Level l-1 is the 2 x 2 box average of level l (at an odd edge the missing texels are left
// out of the average). Level l is cut into tiles_x(l) x tiles_y(l) tiles of T x T texels; tile
// (tx, ty) stores the dim x dim = (T + 2B)^2 texels starting at (T tx - B, T ty - B), so it has a
// B-texel border for filtering; texels outside the level are clamped to its edge.
// Tiles are planar: value(k, x, y) = tile[(k * dim + y) * dim + x].
//
// Parent prediction (section 6: tiles stored as the difference to the up-sampled parent). The
// prediction of tile (l, tx, ty) is the bilinear up-sampling of its parent tile
// (l-1, tx/2, ty/2): level-l texel s (clamped into the level) sits at parent coordinate
// s/2 - 1/4, i.e. 3/4 of parent texel floor(s/2) and 1/4 of its neighbour towards s. All taps
// fall inside the parent tile *with its border* whenever B >= 2, so a client holding only the
// parent tile can decode the child (the paper's add rule). Encoder and decoder predict from the
// *decoded* parent tile (closed loop), so quantisation errors do not accumulate down the levels.
//
// Residual codec. The dim x dim residual of each plane is cut into (dim/8)^2 blocks, each
// DCT-ed and quantised (dct.h: q = round(coefficient / step)). The raw tile payload lists every
// quantised coefficient as a zigzag-signed LEB128 varint, ordered plane, zigzag position, block
// (row-major): grouping equal frequencies of all blocks gives deflate long runs of zeros.
#pragma once
#include <cstddef>
#include <cstdint>
#include <vector>

#include "core/status.h"

namespace btfc::bsvtf {

struct Geometry {
  int width = 0, height = 0;            // full-resolution texels
  int tile = 64, border = 4, comps = 4; // T, B, K
  int levels = 1;                       // L + 1

  int dim() const { return tile + 2 * border; }
  int finest() const { return levels - 1; }
  int level_width(int l) const;
  int level_height(int l) const;
  int tiles_x(int l) const { return (level_width(l) + tile - 1) / tile; }
  int tiles_y(int l) const { return (level_height(l) + tile - 1) / tile; }
  size_t tiles_in_level(int l) const { return size_t(tiles_x(l)) * size_t(tiles_y(l)); }
  size_t tiles_total() const;  // all levels
  size_t tile_floats() const { return size_t(comps) * size_t(dim()) * size_t(dim()); }
  // Most bytes a raw tile payload can have (5-byte varints).
  size_t max_raw_tile_bytes() const { return tile_floats() * 5; }

  // Validates: 1 <= width, height <= 2^20; 8 <= T <= 1024; 2 <= B <= 64; (T + 2B) % 8 == 0;
  // 1 <= K <= 4. Computes `levels`.
  static Result<Geometry> make(int width, int height, int tile, int border, int comps);
};

// Planar image of K planes, w x h texels each: img[(k * h + y) * w + x].
std::vector<float> downsample(const std::vector<float>& img, int w, int h, int comps);

// Copies tile (tx, ty) of a level image (planar, lw x lh) into `tile` (tile_floats()).
void extract_tile(const Geometry& g, const float* img, int lw, int lh, int tx, int ty, float* tile);

// Prediction of tile (level >= 1, tx, ty) from its parent tile; both tile_floats().
void predict_from_parent(const Geometry& g, int level, int tx, int ty, const float* parent, float* pred);

// Seed 000 eq. 8: w = 1/T^2 sum over the T x T interior of sum over planes (tile - pred)^2.
// `pred` null: the difference to nothing (level 0's weight, its mean square value).
double tile_weight(const Geometry& g, const float* tile, const float* pred);

// Quantises `residual` (tile_floats()) with the 64 natural-order steps; returns the raw payload
// and writes the decoded residual (what decode_residual gives back) into `decoded`.
std::vector<uint8_t> encode_residual(const Geometry& g, const float* residual, const float* steps, float* decoded);
// Parses a raw payload (exactly tile_floats() varints, nothing left over) into the residual.
// corrupt_data on a malformed payload.
Status decode_residual(const Geometry& g, const uint8_t* raw, size_t n, const float* steps, float* residual);

// zlib streams (deflate level 9); inflate must produce exactly `raw_size` bytes.
std::vector<uint8_t> deflate_bytes(const std::vector<uint8_t>& raw);
Status inflate_bytes(const uint8_t* data, size_t n, size_t raw_size, std::vector<uint8_t>& out);

}  // namespace btfc::bsvtf
