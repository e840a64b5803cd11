// BSVTF: the level-of-detail streaming file of an `fmf` model. Paper: C. Schwartz, R. Ruiters,
// R. Klein, "Level-of-Detail Streaming and Rendering using Bidirectional Sparse Virtual Texture
// Functions", Computer Graphics Forum 32(7), Pacific Graphics 2013 (sections 3, 5, 6 and 7).
//
// What it holds. Every factorized block b of the fmf model (color=rgb: one block "rgb";
// color=dfmf: "y", "u", "v") has eigen-ABRDFs U (rows x C) and eigen-textures SxV (texels x C).
// The eigen-textures are grouped K = 4 at a time into RGBA virtual textures (section 7: "we store
// four values V'(x) per pixel as RGBA channels"; a tile of 72 x 72 x 4 half floats is the paper's
// 40.5 KB); group g of block b holds components 4g .. 4g+3 (missing ones of the last group are
// zero). Each virtual texture is a mip pyramid cut into T x T tiles with a B-texel border
// (T = 64, B = 4; bsvtf_tile.h has the geometry). Every tile is stored as its difference to the
// bilinear up-sampling of its decoded parent (section 6), 8 x 8 DCT, quantised by a JPEG-like
// quality (dct.h: quality q quantises a block's value range like libjpeg quantises 0..255 at q;
// the 64 steps are stored per block), the coefficients deflated (zlib). Each tile carries its
// weight w(i, l, l-1) of eq. 8, for the tile cache's priority P = w v (tile_cache.h). The
// eigen-ABRDF columns of each group, packed RGBA as half floats (the paper's 534 KB packets for
// 151 x 151 x 3 rows), are packets interleaved with the tiles: each group's packet comes right
// before its level-0 tile, so a client can start rendering after the first packet + tile.
//
// File format, version 1.0 and 1.1 (little-endian; also in docs/FORMAT.md, "BSVTF"):
//   header (header_bytes) | directory (num_entries x 40 bytes) | payloads (data_bytes)
//   Header:  0  char[8] magic "BSVTF\r\n\x1a"     8 u16 major = 1    10 u16 minor = 0 (1 with model 13)
//           12  u32 header_bytes   16 u32 width   20 u32 height      24 u32 tile T
//           28  u32 border B       32 u32 comps K 36 u32 levels      40 u32 quality (1..100)
//           44  u32 color model (0 = FMF rgb: block "rgb", rows = channels x lights x views;
//                                11 = DFMF: blocks "y","u","v", rows = lights x views;
//                                13 = DFMF as 11 with its own luminance offset, stored below)
//           48  u32 channels       52 u32 num_lights  56 u32 num_views   60 u32 num_blocks
//           64  u64 num_entries    72 u64 data_bytes
//           80  lights (num_lights x 3 f32, unit xyz), views (num_views x 3 f32)
//               blocks: num_blocks x { char[8] name (NUL padded); u32 rows; u32 components C;
//                       u32 groups = ceil(C / K); f32 range (max - min of SxV); f32 step[64]
//                       (natural order, the quantisation steps of its tiles) }
//               model 13 only: f32 luminance offset e (finite, > 0)
//               u32 directory crc32; u32 header crc32 (of every header byte before it)
//   Directory entry: 0 u8 kind (1 = ABRDF packet, 2 = tile)  1 u8 level  2 u16 block  4 u32 group
//           8 u32 tx  12 u32 ty  16 u64 offset (from the file start)  24 u32 stored bytes
//           28 u32 raw bytes (inflated)  32 f32 weight w(i, l, l-1) (0 for packets)  36 u32 crc32
//           of the stored bytes.
//   Order (pinned; readers check every entry against it): virtual textures t = (block, group) in
//   block-then-group order; level 0: for each t its packet then its tile; then levels 1 .. L:
//   for each t its tiles row by row. Payloads follow in directory order, back to back.
//   Payload = one zlib stream. Packet raw: rows x K half floats, packet[r K + k] = U[r][4g + k].
//   Tile raw: the varint coefficients of bsvtf_tile.h (K x dim^2 of them).
//   The weight is f32, not the paper's half: w is a mean *squared* value, which overflows half
//   (65504) for HDR eigen-textures above ~256.
// Evaluation (what a renderer does with the decoded data): rho(x, l, v) = sum_c U_c(row) V_c(x)
// per block; color 0: row = c + channels (l + lights v) gives colour c directly; color 11:
// Y' U' V' from the three blocks (row = l + lights v), Y = exp(Y') - e, U = U' (Y + e),
// V = V' (Y + e), RGB = [1 0 1.13983; 1 -0.39465 -0.5806; 1 2.03211 0] YUV (codecs/fmf/fmf.h),
// e = 1e-5 (Bonn's) for color 11, the stored offset for color 13. Why 13 and not an offset for
// every dfmf file: btfc's dfmf encodes pick their offset from the data (the automatic offset of
// codecs/fmf/fmf.h), so most dfmf models have no BSVTF otherwise, while files of Bonn's offset
// stay the 1.0 bytes; a 1.0 reader refuses a model-13 file by its unknown colour model.
//
// Contracts: write_bsvtf writes "<path>.tmp-<pid>" and renames; on failure nothing is left.
// BsvtfReader::open reads and validates the header and directory (magic, version, CRCs, every
// size and offset against the file length and the geometry) before allocating by any count from
// the file; payloads are read on demand and their CRC and exact inflated size checked. Errors
// name the file. Deterministic: same model and options -> identical bytes.
#pragma once
#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "codecs/codec.h"
#include "formats/bsvtf/bsvtf_tile.h"

namespace btfc {

struct BsvtfOptions {
  int quality = 95;  // 1..100, JPEG-like (dct.h); 95: tiles ~6:1 vs half, SSIM vs fmf ~0.98 (docs/benchmarks.md)
  int tile = 64;     // T: tile interior texels (the paper's 64)
  int border = 4;    // B: texels of border on each side (the paper's 4)
};

struct BsvtfReport {
  size_t textures = 0, tiles = 0;  // virtual textures (groups of 4 eigen-textures), tiles in all levels
  int levels = 0;
  uint64_t file_bytes = 0, header_bytes = 0;  // header_bytes: header + directory
  uint64_t tile_bytes = 0, packet_bytes = 0;  // stored payloads
  uint64_t tile_raw_half_bytes = 0;  // the tiles uncompressed as half floats (dim^2 x 4 x 2 each)
  uint64_t eigen_f32_bytes = 0, eigen_f16_bytes = 0;  // the eigen-textures themselves (texels x C)
  double psnr = 0;     // eigen-textures vs the model's, dB, peak = each block's range
  double rel_l2 = 0;   // ||SxV - decoded||_F / ||SxV||_F over all blocks (= the ABRDF error, U orthonormal)
  double max_abs = 0;
  std::vector<std::pair<std::string, double>> block_psnr;
  double seconds = 0;
};

struct FmfFactorsView;  // codecs/fmf/fmf.h
// The colour model a factorization is written as: 0 (rgb), 11 (dfmf with Bonn's offset 1e-5),
// 13 (dfmf with another offset), or -1 when BSVTF cannot hold it (a Bonn colour model other
// than 0 and 11). write_bsvtf and the export's attach_bsvtf both decide by it.
int bsvtf_color_model(const FmfFactorsView& f);

// Writes the BSVTF of an fmf model. invalid_argument: not an fmf model, bad options;
// unsupported: a Bonn colour model other than 0 (rgb) and 11 (dfmf; written as colour model 13
// when its luminance offset is not 1e-5); io_error on write.
Status write_bsvtf(const Model& fmf_model, const BsvtfOptions& options, const std::string& path, BsvtfReport* report);

struct BsvtfBlock {
  std::string name;
  uint32_t rows = 0, components = 0, groups = 0;
  float range = 0;
  std::array<float, 64> steps{};
};

struct BsvtfEntry {
  enum Kind : uint8_t { packet = 1, tile = 2 };
  uint8_t kind = 0, level = 0;
  uint16_t block = 0;
  uint32_t group = 0, tx = 0, ty = 0;
  uint64_t offset = 0;
  uint32_t stored = 0, raw = 0;
  float weight = 0;
  uint32_t crc = 0;
};

// Directory positions (the pinned order above) for `textures` virtual textures.
size_t bsvtf_packet_entry(size_t texture);
size_t bsvtf_tile_entry(const bsvtf::Geometry& g, size_t textures, size_t texture, int level, int tx, int ty);

class BsvtfReader {
 public:
  static Result<BsvtfReader> open(const std::string& path);

  const std::string& path() const { return m_path; }
  const bsvtf::Geometry& geometry() const { return m_geo; }
  int quality() const { return m_quality; }
  int color_model() const { return m_color; }  // 0, 11 or 13
  float luminance_offset() const { return m_offset; }  // e of models 11 (1e-5) and 13 (stored)
  int channels() const { return m_channels; }
  const DirectionSet& lights() const { return m_lights; }
  const DirectionSet& views() const { return m_views; }
  const std::vector<BsvtfBlock>& blocks() const { return m_blocks; }
  const std::vector<BsvtfEntry>& entries() const { return m_entries; }
  uint64_t header_bytes() const { return m_header_bytes; }  // header + directory
  uint64_t file_bytes() const { return m_file_bytes; }
  // Virtual textures in file order: texture t is (block, group).
  size_t textures() const { return m_texture_block.size(); }
  int texture_block(size_t t) const { return m_texture_block[t]; }
  int texture_group(size_t t) const { return m_texture_group[t]; }

  // Eigen-ABRDF packet of texture t: rows x K floats.
  Result<std::vector<float>> read_packet(size_t t) const;
  // Decodes tile (t, level, tx, ty) into `out` (tile_floats()): its residual plus the
  // prediction from `parent`, the decoded parent tile (null, and ignored, at level 0).
  Status read_tile(size_t t, int level, int tx, int ty, const float* parent, float* out) const;
  // Every tile of texture t decoded: [level][tile (row-major) * tile_floats() + ...].
  Result<std::vector<std::vector<float>>> decode_texture(size_t t) const;
  // Block b's eigen-textures (texels x C, row-major like the model's SxV) and eigen-ABRDFs
  // (rows x C) as decoded from the file.
  Result<std::vector<float>> decode_eigen_textures(int b) const;
  Result<std::vector<float>> decode_eigen_abrdfs(int b) const;

 private:
  Result<std::vector<uint8_t>> payload(size_t entry) const;

  std::string m_path;
  std::shared_ptr<int> m_fd;  // closed when the last copy goes
  bsvtf::Geometry m_geo;
  int m_quality = 0, m_color = 0, m_channels = 0;
  float m_offset = 1e-5f;
  DirectionSet m_lights, m_views;
  std::vector<BsvtfBlock> m_blocks;
  std::vector<BsvtfEntry> m_entries;
  std::vector<int> m_texture_block, m_texture_group;
  uint64_t m_header_bytes = 0, m_file_bytes = 0;
};

}  // namespace btfc
