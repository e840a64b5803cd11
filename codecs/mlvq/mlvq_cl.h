// mlvq on OpenCL (kernels/mlvq.cl): the SSIM codebook search (paper section 4.3, "the
// computation of SSIM errors is computed in parallel for all data vectors in the codebooks"),
// the colour conversion and batched decoding, each with the plain C++ reference it is tested
// against (tests/mlvq_test.cpp). The references compute the kernels' arithmetic in the same
// order in float, so results agree to float rounding.
#pragma once
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "core/status.h"

namespace btfc::mlvq {

struct Hierarchy;

// Best entry for each of B candidates among K codebook prototypes. Row-major candidates Xl
// (B x dl, luminance) / Xc (B x dc, chromaticity) and prototypes El / Ec (K x dl / dc); dl or dc
// may be 0 (that part is not compared). xm: per candidate (sum x, sum x^2, peak, sum xc,
// sum xc^2); em: per entry (sum e, sum e^2, sum ec, sum ec^2). Similarity: luminance SSIM up to
// the least-squares scale (dynamic range = the candidate's peak), chromaticity SSIM unscaled
// (range 1); the score is the margin over the thresholds tl / tc, the minimum of (lum SSIM - tl)
// and (chroma SSIM - tc) over the parts present; the best entry has the largest score.
struct SearchProblem {
  int B = 0, K = 0, dl = 0, dc = 0;
  const float *Xl = nullptr, *Xc = nullptr, *El = nullptr, *Ec = nullptr;
  const double *xm = nullptr, *em = nullptr;
  float tl = 0, tc = 0;
};
struct SearchResult {
  std::vector<int> idx;  // -1 when K = 0
  std::vector<float> sim, scale;  // sim: the best score (margin), -3 when K = 0
};
void ssim_search_reference(const SearchProblem& p, SearchResult& r);
Status ssim_search_cl(const SearchProblem& p, SearchResult& r);

// Colour conversion of n RGB triples to (L, r, g) (rgb_to_lrg).
void rgb_to_lrg_reference(std::span<const float> rgb, float* lrg);
Status rgb_to_lrg_cl(std::span<const float> rgb, float* lrg);

// The hierarchy flattened for the decoding kernel: one index array and one float array in
// parallel (a book's children at offset o of `idx`, its scales at the same offset of `val`;
// chromaticity books carry scales of 1), plus offsets in `meta`:
//   meta[0] scheme, meta[1..4] n(level 1..4), meta[5 + k - 1] rgb book k, meta[9 + k - 1] lum
//   book k, meta[13 + k - 1] chroma book k, meta[17] M pairs (idx, interleaved lum, chroma),
//   meta[18] level-1 luminance values (val), meta[19] level-1 chromaticity values (val),
//   meta[20] texel entries (idx) and scales (val).
struct FlatModel {
  std::vector<int> meta;
  std::vector<uint32_t> idx;
  std::vector<float> val;
};
FlatModel flatten(const Hierarchy& h);

// Batched evaluation: query i = texel[i] at grid coordinates coord[4 i .. 4 i + 3] = (phi,
// theta, alpha, beta) in node units (grid_coord); out: 3 floats per query (RGB).
void eval_flat_reference(const FlatModel& f, std::span<const int> texel, std::span<const float> coord, float* out);

class DeviceModel {
 public:
  static Result<std::shared_ptr<DeviceModel>> upload(const FlatModel& f);
  Status eval(std::span<const int> texel, std::span<const float> coord, float* out) const;
  ~DeviceModel();
  struct Impl;

 private:
  std::unique_ptr<Impl> m;
};

}  // namespace btfc::mlvq
