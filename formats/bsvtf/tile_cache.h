// Offline simulator of the BSVTF tile cache (seed 000 sections 3, 5, 5.1, 5.2 and 6), to measure
// quality against cache size (the paper's Fig. 4) and against streamed bytes (Fig. 5) without a GPU.
//
// Scene. The flat sample lies in the plane z = 0, texel (s, t) at world (s, t) (texel units). A
// perspective camera (fov, screen size) follows a deterministic path: "fly" circles the sample,
// coming from far above (the whole sample small on screen) down to a close grazing view and back
// out; "still" holds the path's close grazing view (for streaming curves). Per screen pixel the
// ray hits texel (s, t); the texel footprint fp = max(|dPi/dx|, |dPi/dy|) (finite differences to
// the next pixel's ray) gives the needed level l = clamp(ceil(L - log2 fp), 0, L) (eq. 1, rounded
// towards the finer level) and eq. 2 its tile. That is the feedback image. Pixel votes v(i, l)
// (eq. 9) count the pixels that need tile i at level l or a descendant; all virtual textures of
// the sample share them ("repeated in the spatial layout of the components").
//
// Cache (section 5.1 / 5.2). N tile slots shared by all virtual textures. Each frame, repeat:
//  - candidate adds: tiles not resident whose parent is resident (level 0: always addable),
//    not already covered by all their children, priority P = w(i, l, l-1) v(i, l) > 0;
//  - an eigen-ABRDF packet not yet streamed is sent first when its priority
//    sum over the texture's resident tiles of v ||T||^2 / T^2 (section 6) is >= the best P;
//  - a free slot: add the best tile. Post-condition: a parent all of whose children are now
//    resident is removed (it no longer shows) -- unless some pixel needs exactly that parent's
//    level there: the renderer below shows the needed level when it is resident, so such a
//    parent still shows (the paper's renderer shows the finest resident level instead);
//  - cache full: the cheapest way to free a slot, cost c of eq. 10 (sum over the revealed levels
//    k of w(ancestor at k, k, k-1) v(i, l), k from the revealed level + 1 to l):
//      swap: two resident tiles whose nearest common *non-resident* ancestor A gets inserted
//            (the paper's swap), or
//      evict: one resident tile whose nearest resident ancestor then shows (cost of one term;
//            the case the paper's swap leaves out: tiles that scrolled out of view have v = 0
//            and must be droppable while their parent is resident).
//    If c < P: free the slot that way, then add. Otherwise the frame is done.
//  Tiles added in a frame are not evicted or swapped out in the same frame (no cycles; only the
//  covered-parent rule may drop them); the best add's parent is never the one removed. Once no operation helps, the remaining packets of textures with
//  resident tiles are sent by priority. With a bandwidth limit (bytes per frame) the frame stops
//  when the next tile or packet would exceed it (one item always fits, so large packets pass).
// Streaming: every tile or packet is sent once (the client keeps received data in RAM, section 6);
// the header and directory are sent before the first frame. Bytes are the stored payload sizes.
//
// Measures per frame, against the converged state (every needed tile at the needed level, every
// packet): error = sqrt(sum E / sum V^2) with E of eq. 7 summed over pixels and all
// eigen-textures (bilinear lookups of the shown level: the needed one if resident, else the
// finest resident coarser one, else the nearest resident finer one);
// ssim = SSIM of the rendered luminance (core/metrics.h, range = the converged image's peak) of
// the sample shaded at one (light, view) pair: rho = sum_c U_c(row) V~_c(x) per block (colour
// model in bsvtf.h), components whose packet has not arrived contribute nothing.
// Deterministic: same file and options -> same numbers. Memory: every decoded tile is held
// (tile_floats() x 4 bytes each, 83 KB at T = 64): about 1.7 x the eigen-textures as float
// (borders x 1.27, mip levels x 4/3).
// Cost per cache operation is linear in the number of tiles (plain scans, no priority queues),
// fine for the few thousand tiles of the samples here.
#pragma once
#include <cstdint>
#include <vector>

#include "formats/bsvtf/bsvtf.h"

namespace btfc {

struct CameraPathOptions {
  enum class Kind { fly, still } kind = Kind::fly;
  int frames = 60;
  int width = 320, height = 240;  // screen pixels
  double fov_deg = 60;
};

struct TileCacheOptions {
  size_t cache_tiles = 64;
  uint64_t bandwidth = 0;     // bytes per frame; 0 = unlimited (the cache converges every frame)
  int light = -1, view = -1;  // shading direction indices; -1: lights / 2 and view 0
  CameraPathOptions path;
};

struct TileCacheFrame {
  int frame = 0;
  size_t resident = 0, working_set = 0;  // tiles in the cache / tiles the frame's feedback asks for
  int adds = 0, swaps = 0, evictions = 0, covered = 0, packets = 0;
  uint64_t bytes = 0;  // streamed so far (cumulative)
  double error = 0, ssim = 1;
};

struct TileCacheRun {
  std::vector<TileCacheFrame> frames;
  double mean_error = 0, mean_ssim = 0;
  uint64_t bytes = 0;
};

// One pixel of the feedback image: the texel it shows (full-resolution units) and the level it
// needs; `hit` false when the ray misses the sample.
struct FeedbackPixel {
  float s = 0, t = 0;
  int level = 0;
  bool hit = false;
};
// The feedback image of `frame` (0 .. path.frames - 1; width x height, row-major); errors on bad
// options.
Result<std::vector<FeedbackPixel>> feedback_image(const bsvtf::Geometry& g, const CameraPathOptions& path, int frame);

class TileCacheSim {
 public:
  // Decodes every tile and packet of the file once (the simulator's "server").
  static Result<TileCacheSim> make(const BsvtfReader& file);
  Result<TileCacheRun> run(const TileCacheOptions& options) const;
  // The converged image of `frame` on `options`' path (every needed tile at its level, every
  // packet), shaded at `options`' light and view by the file's colour model (models 11 and 13:
  // Y' U' V' through the file's luminance offset): the luminance each frame's SSIM compares
  // against, row-major, NaN where the ray misses the sample. For tests and tools.
  Result<std::vector<float>> converged_luminance(const TileCacheOptions& options, int frame) const;

  size_t textures() const { return m_textures; }
  size_t tiles() const { return m_textures * m_per_texture; }
  uint64_t tile_slot_bytes() const { return uint64_t(m_geo.tile_floats()) * 2; }  // one half-float slot

 private:
  friend struct CacheRunState;
  bsvtf::Geometry m_geo;
  size_t m_textures = 0, m_per_texture = 0;
  std::vector<size_t> m_level_base;          // spatial id of (level, 0)
  std::vector<std::vector<float>> m_tiles;   // [texture] all levels' decoded tiles, spatial-id order
  std::vector<float> m_weight, m_energy;     // per global tile (texture * per_texture + spatial id)
  std::vector<uint32_t> m_bytes;             // stored bytes per global tile
  std::vector<std::vector<float>> m_packets; // [texture] rows x K
  std::vector<uint32_t> m_packet_bytes;
  std::vector<int> m_block, m_group;         // per texture
  std::vector<uint32_t> m_block_rows, m_block_components;
  bool m_dfmf = false;     // colour model 11 or 13: blocks y, u, v
  float m_offset = 1e-5f;  // their luminance offset
  int m_channels = 3, m_lights = 1, m_views = 1;
  uint64_t m_header_bytes = 0;
};

}  // namespace btfc
