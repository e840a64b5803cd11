// Internal pieces of the mlvq codec, shared by its .cpp files and tests/mlvq_test.cpp.
// Not part of btfc's public API; codecs/mlvq/mlvq.h is the contract.
#pragma once
#include <array>
#include <memory>
#include <mutex>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "codecs/codec.h"
#include "core/interp.h"

namespace btfc::mlvq {

class DeviceModel;  // mlvq_cl.h

// ---- 4D parameterisation (resample.cpp) ---------------------------------------------------------
// Axes, outermost first (the codebook levels 4, 3, 2, 1):
//   phi_v   view azimuth, nphi nodes at 360 / nphi degree steps from 0 (periodic),
//   theta_v view polar angle, ntheta nodes uniform in [0, 90] degrees,
//   alpha   light "onion slice" angle, nalpha nodes uniform in [-90, 90] degrees,
//   beta    light elevation out of the slice plane, nbeta nodes uniform in sin(beta) over
//           [-1, 1] (formats.md 2.5 useCosBeta; odd counts put a node at beta = 0).
// The illumination axes are relative to the view azimuth: the light is rotated by -phi_v about
// the normal, l' = Rz(-phi_v) l, then alpha = atan2(l'x, l'z), beta = asin(l'y), so that
// l' = (cos b sin a, sin b, cos b cos a). The view then lies in the x-z plane and the mirror
// direction of every view is at (alpha, beta) = (-theta_v, 0): specular peaks line up across
// phi_v, which is what lets 3D slices of different azimuths share codebook entries.
// Node order: node = beta + nbeta (alpha + nalpha (theta + ntheta phi)), so a level-k slice
// (fixed coordinates above k) is a contiguous run of slice_len(k) nodes.
//
// Layout "measured" (the default since payload version 2; see mlvq.h for why): the same four
// levels over the *measured* directions instead of a resampled grid. Level 4's axis (nphi
// nodes) are groups of ntheta consecutive views, level 3's (ntheta) the views of a group,
// level 2's (nalpha) groups of nbeta consecutive lights, level 1's (nbeta) the lights of a
// group: node (ip, it, ia, ib) is view ip ntheta + it, light ia nbeta + ib, clamped to the last
// view / light where the groups overhang the sets (the padding repeats a measured value, so
// it costs no new codebook entry shapes). Grid coordinates of a measured (light, view) are
// those integers; arbitrary directions are interpolated between measured ones (core/interp.h).
enum Layout : int { k_layout_grid = 0, k_layout_measured = 1 };
struct Grid {
  int nphi = 16, ntheta = 7, nalpha = 11, nbeta = 11;
  int layout = k_layout_grid;
  int nl = 0, nv = 0;  // measured layout: the BTF's light / view counts
  bool measured() const { return layout == k_layout_measured; }
  // Children per entry at level k (4: phi, 3: theta, 2: alpha, 1: beta values).
  int n(int level) const { return level == 4 ? nphi : level == 3 ? ntheta : level == 2 ? nalpha : nbeta; }
  size_t slice_len(int level) const {
    size_t s = 1;
    for (int k = 1; k <= level; ++k) s *= size_t(n(k));
    return s;
  }
  size_t size() const { return slice_len(4); }
};

// The measured layout of a BTF: group sizes nbeta = ceil(sqrt(nL)), nalpha = ceil(nL / nbeta),
// ntheta = ceil(sqrt(nV)), nphi = ceil(nV / ntheta) (81 directions: 9 x 9).
Grid measured_grid(const BtfDesc& d);
// Measured layout: the (light, view) of a node index.
void node_measured(const Grid& g, size_t node, uint32_t& light, uint32_t& view);
// The stencil of measured (light, view): the grid's multilinear stencil, or (measured layout)
// weight 1 on the node of that pair.
struct Stencil;
Stencil measured_stencil(const Grid& g, const BtfDesc& d, size_t light, size_t view);

// Continuous grid coordinates of a (light, view) pair: node units on each axis (phi wraps).
struct GridCoord {
  float phi = 0, theta = 0, alpha = 0, beta = 0;
};
GridCoord grid_coord(const Grid& g, const Vec3& wl, const Vec3& wv);
// Directions of node (iphi, itheta, ialpha, ibeta).
void node_dirs(const Grid& g, int iphi, int itheta, int ialpha, int ibeta, Vec3& wl, Vec3& wv);

// The 2 x 2 x 2 x 2 multilinear stencil of a coordinate: per level k (index k-1 = beta, alpha,
// theta, phi) two node indices and weights (weights of a level sum to 1).
struct Stencil {
  int i[4][2];
  float w[4][2];
};
Stencil stencil(const Grid& g, const GridCoord& c);

// Colour model (the paper's codebook M splits luminance and chromaticity):
// L = (R + G + B) / 3, r = R / (R + G + B), g = G / (R + G + B); chromaticity (1/3, 1/3) when
// R + G + B = 0. Negative inputs are clamped to 0 first (a VQ of non-negative shapes with
// non-negative scales cannot represent them). Inverse: R = 3 L r, G = 3 L g, B = 3 L (1 - r - g).
void rgb_to_lrg(const float* rgb, float* lrg);
void lrg_to_rgb(const float* lrg, float* rgb);

// For every grid node the 9 (ABRDF offset of channel 0, weight) pairs of the measured-direction
// interpolation (core/interp.h), so extracting a slice is a gather.
struct ResamplePlan {
  Grid grid;
  int channels = 3;
  bool direct = false;  // measured layout: one tap of weight 1 per node
  std::vector<std::array<uint32_t, 9>> off;
  std::vector<std::array<float, 9>> w;
};
ResamplePlan make_plan(const BtfDesc& d, const Grid& g);
// Resamples nodes [first, first + count) of one texel's ABRDF: lum[count], chroma[2 count]
// (interleaved r, g). Either output may be null.
void extract(const ResamplePlan& p, const float* abrdf, size_t first, size_t count, float* lum, float* chroma);

// ---- the hierarchy (codebook.cpp builds it, mlvq_model.cpp decodes it) --------------------------
enum Part : int { k_rgb = 0, k_lum = 1, k_chroma = 2 };

// One codebook at level k. Levels > 1: K entries of n children (index into level k-1's book of
// the part below, or into the merge book M when k - 1 == scheme) with a scale each (rgb and
// lum; the scale multiplies luminance only: chromaticity is scale-free). Level 1: K entries of
// nbeta luminance values (lum) or nbeta (r, g) pairs (chroma).
struct Book {
  uint32_t K = 0;
  uint32_t n = 0;
  std::vector<uint32_t> child;  // K * n
  std::vector<float> scale;     // K * n (dequantized), empty for chroma
  std::vector<uint16_t> scode;  // the stored scale codes (quantize_scales), lo / hi their range
  float lo = 0, hi = 0;
  std::vector<float> values;    // level 1: K * nbeta (lum) or K * 2 nbeta (chroma)
};

struct Hierarchy {
  Grid grid;
  int scheme = 2;    // luminance / chromaticity split at this level (1..4)
  int scale_bits = 8;
  // Level-1 values: 0 = f16 (payload version 1), else uniform steps of 2^-value_bits stored as
  // a zq tensor (core/quant.h: integers, zstd). Luminance is normalized to a maximum of 1 per
  // entry and chromaticity lies in [0, 1], so one step fits every column.
  int value_bits = 0;
  Book rgb[5], lum[5], chroma[5];  // by level 1..4: rgb for k > scheme, lum / chroma for k <= scheme
  std::vector<uint32_t> merge_lum, merge_chroma;  // M: pairs (index into lum[s], chroma[s])
  std::vector<uint32_t> texel_idx;                // per texel: entry of level 4 (rgb[4], or M when scheme = 4)
  std::vector<float> texel_scale;
  std::vector<uint16_t> texel_scode;
  float texel_lo = 0, texel_hi = 0;
  uint32_t merge_size() const { return uint32_t(merge_lum.size()); }
};

// Luminance / chromaticity / RGB of one node of a texel: chained lookups from the texel's entry
// (coord[k] = node index at level k, coord[0] unused).
void node_lrg(const Hierarchy& h, size_t texel, const int coord[5], float lrg[3]);
// node_lrg of n nodes of one texel (coord[j], lrg[j]), the walks interleaved level by level: the
// same values, their loads in flight together.
void node_lrg_many(const Hierarchy& h, size_t texel, const int (*coord)[5], size_t n, float (*lrg)[3]);
// Decodes a whole level-k slice of entry `idx` of part `part` (rgb slices end in M), multiplied
// by `sc`, into lum[slice_len(k)] and (unless null) chroma[2 slice_len(k)].
void decode_slice(const Hierarchy& h, int level, Part part, uint32_t idx, float sc, float* lum, float* chroma);
// Full grid of a texel.
void decode_texel(const Hierarchy& h, size_t texel, float* lum, float* chroma);

// ---- SSIM of vectors (ssim_scan.cpp) ------------------------------------------------------------
// SSIM (Wang et al. 2004, one global window) between x and s e from their moments over n values:
// sums of x, x^2, e, e^2, x e. `scaled`: s = max(0, <x, e> / <e, e>) (the entry matches up to a
// scale, reported in *scale), else s = 1. Dynamic range L: C1 = (0.01 L)^2, C2 = (0.03 L)^2.
double ssim_from_moments(double n, double sx, double sxx, double se, double see, double sxe, double L, bool scaled,
                         double* scale);

// The codebook search's scan (leader_pass): one candidate against a run of entries, margins over
// the thresholds as the search defines them, with ssim_from_moments' bits for every pair.
// Entries' terms that do not depend on the candidate, by entry (appended as entries are made).
struct EntryTerms {
  std::vector<double> see_l, me_l, q_l, me_c, q_c;
  // An entry with luminance sums se, see over n_lum values and chromaticity sums sec, seec over
  // n_chroma (a part absent: n = 0).
  void add(double n_lum, double n_chroma, double se, double see, double sec, double seec);
};
struct ScanCandidate {
  double n_lum = 0, sx = 0, sxx = 0, L = 0;  // luminance: values (0: no luminance part), sums, peak
  double n_chroma = 0, sxc = 0, sxxc = 0;    // chromaticity (range 1)
  double thr_l = 0, thr_c = 0;
};
// For entries j0 .. j0 + k - 1, with gl[i] / gc[i] = <x, e_{j0 + i}> of the luminance /
// chromaticity parts (floats, as the search's GEMMs give them; a part absent: unused):
//   margin[i] = min(lum SSIM - thr_l, chroma SSIM - thr_c) over the parts present, where
//               lum SSIM = ssim_from_moments(n_lum, sx, sxx, se, see, gl[i], L, true, &s),
//               chroma SSIM = ssim_from_moments(n_chroma, sxc, sxxc, sec, seec, gc[i], 1, false)
//               (the luminance term is 2 when there is none),
//   scale[i]  = s (1 without luminance).
// The search takes the first entry of the largest margin, a margin >= 0 being a match.
void ssim_margins(const ScanCandidate& x, const EntryTerms& e, size_t j0, size_t k, const float* gl, const float* gc, double* margin,
                  double* scale);

// ---- noise-adaptive thresholds (noise.cpp) -----------------------------------------------------
// Per (light, view) image (index l + nl v): the noise variance of luminance L and of the
// chromaticity (mean of r and g), by Donoho's MAD estimator on the finest diagonal Haar
// details of 2 x 2 texel blocks (at most max_blocks blocks on a regular sub-grid), lowered where
// the same detail repeats in the partner image (same light, nearest other view; noise.cpp: that
// is texture, not noise). Zero when the BTF is narrower or lower than 2 texels.
struct NoiseEstimate {
  std::vector<float> lum_var, chroma_var;
};
NoiseEstimate estimate_noise(const Btf& btf, size_t max_blocks = 1024);
// Per level k (index 1..4): the median over the level-k slices of `sample_texels` evenly spaced
// texels of the expected SSIM of two noisy copies of a slice, (2 s2 + C2) / (2 s2 + 2 n2 + C2)
// with n2 the slice's mean resampled noise variance (sum_j w_j^2 sigma_j^2 per node) and s2 its
// variance minus n2: for luminance (C2 from the slice's peak; all-zero slices skipped) and
// chromaticity (range 1). 1 where nothing was measured.
struct NoiseCeilings {
  double lum[5] = {1, 1, 1, 1, 1}, chroma[5] = {1, 1, 1, 1, 1};
};
NoiseCeilings noise_ceilings(const Btf& btf, const ResamplePlan& plan, const NoiseEstimate& ne, size_t sample_texels = 64);

// The stored form of a level-1 value (f16 rounding, or the zq step): the encoder applies it
// before refitting the scales, so the model in memory equals its file.
float store_value(float v, int value_bits);

struct EncodeOptions {
  Grid grid;
  int scheme = 2;
  int value_bits = 0;
  // SSIM thresholds by level, for luminance (and RGB levels' luminance part) and chromaticity.
  double thr[5] = {0, 0.98, 0.97, 0.95, 0.95};
  double thr_chroma[5] = {0, 0.98, 0.97, 0.95, 0.95};
  int scale_bits = 8;
  bool cl_search = false;  // SSIM search through kernels/mlvq.cl
};

struct EncodeReport {
  uint64_t entries[3][5] = {};  // [part][level]
  uint64_t merge_entries = 0;
  double mean_texel_ssim = 0;   // luminance SSIM of resampled vs reconstructed 4D vectors
  double resample_rel_rmse = 0; // measured -> grid -> measured on a texel sample, no quantization
  double seconds = 0;
  double pass_seconds[3][5] = {};  // [part][level]: the leader passes (search) per codebook
  double refit_seconds = 0;        // values, scale refits, quality estimate
};

Result<Hierarchy> encode_hierarchy(const Btf& btf, const EncodeOptions& o, EncodeReport& rep);

// ---- scale quantization (codebook.cpp) -------------------------------------------------------------
// Log-uniform codes: 0 = zero, 1..2^bits - 1 span [lo, hi] = ln of the smallest / largest positive
// value of the stream. quantize_scales rounds `v` in place and returns the codes.
struct ScaleCodes {
  std::vector<uint16_t> code;
  float lo = 0, hi = 0;
};
ScaleCodes quantize_scales(std::vector<float>& v, int bits);
float dequantize_scale(uint16_t code, float lo, float hi, int bits);

// ---- Huffman / bit packing of index streams (huffman.cpp) ----------------------------------------
// Stream format: byte 0 = mode (0: plain, 1: Huffman). Plain: values LSB-first in
// bits(alphabet) = ceil(log2(alphabet)) bits each (0 bits when alphabet = 1). Huffman: a
// canonical code of lengths <= 24: 5 bits per symbol of the alphabet (its code length, 0 = unused)
// then the codes MSB-first, all in one LSB-first bit stream.
int plain_bits(uint32_t alphabet);
struct CodedStream {
  std::vector<uint8_t> bytes;
  uint64_t plain_bytes = 0, huffman_bytes = 0;  // both candidates, with the mode byte
  bool huffman = false;
};
CodedStream encode_indices(std::span<const uint32_t> v, uint32_t alphabet, bool allow_huffman);
// Decodes exactly `count` indices < alphabet; errors (corrupt_data, message `what`-prefixed) on
// truncation, an invalid code table, an undecodable code, or an index out of range.
Result<std::vector<uint32_t>> decode_indices(std::span<const uint8_t> bytes, size_t count, uint32_t alphabet,
                                             const std::string& what);

// ---- model (mlvq_model.cpp) ------------------------------------------------------------------------
// 1: grid layout only (header word 7 = 0). 2: header word 7 = layout (0 grid, 1 measured);
// level-1 luminance values either f16 (as in 1) or a zq tensor (core/quant.h). Version-1 files
// read as before.
constexpr uint32_t k_payload_version = 2;

class MlvqModel final : public Model {
 public:
  MlvqModel(BtfDesc desc, std::string spec, Hierarchy h, bool huffman);

  const BtfDesc& desc() const override { return m_desc; }
  const std::string& spec() const override { return m_spec; }
  const Hierarchy& hierarchy() const { return m_h; }
  Status decode(const DecodeRequest& req, Btf& out) const override;
  void eval(int x, int y, int light, int view, float* out) const override;
  Status eval_dir(int x, int y, const Vec3& wl, const Vec3& wv, float* out) const override;
  Status eval_batch(std::span<const EvalQuery> q, float* out) const override;
  Result<std::vector<Tensor>> gpu_tensors() const override;
  Status save(ContainerWriter& w) const override;
  uint64_t payload_bytes() const override;
  ModelStats stats() const override { return m_stats; }
  ModelStats& mutable_stats() { return m_stats; }
  // Payload bytes with every index stream bit-packed, and with the chosen (smaller) coding.
  uint64_t plain_payload_bytes() const;
  // Stored bytes per tensor (what fills the payload), in save() order.
  std::vector<std::pair<std::string, uint64_t>> tensor_bytes() const;

  static Result<std::unique_ptr<Model>> load(const ContainerReader& rd, const Params& p);

 private:
  std::vector<Tensor> tensors(bool allow_huffman, uint64_t* plain_bytes) const;
  BtfDesc m_desc;
  std::string m_spec;
  Hierarchy m_h;
  bool m_huffman = true;
  std::vector<Stencil> m_measured;  // per (light + nL view)
  // Measured layout: arbitrary directions blend the 3 x 3 nearest measured pairs (core/interp.h).
  DirectionInterpolator m_li, m_vi;
  void dir_pairs(const Vec3& wl, const Vec3& wv, uint32_t pair[9], float w[9]) const;
  // The 9 measured pairs around (wl, wv) at `texel`, blended (measured layout only).
  void blend_measured(size_t texel, const Vec3& wl, const Vec3& wv, float rgb[3]) const;
  ModelStats m_stats;
  mutable std::mutex m_dev_mu;  // the device copy for eval_batch, uploaded on first use
  mutable std::shared_ptr<DeviceModel> m_dev;
};

// Value at a stencil (16 chained lookups blended in RGB): the C++ reference of the kernels'.
void eval_stencil(const Hierarchy& h, size_t texel, const Stencil& s, float rgb[3]);

}  // namespace btfc::mlvq
