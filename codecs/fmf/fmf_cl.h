// fmf on OpenCL: batched evaluation and region / direction-subset decode (kernels/fmf.cl),
// each with the plain C++ reference it is tested against.
//
// PackedFactors is the kernels' layout: all blocks padded to one component count C,
//   U   [blocks][rows_per_block][C],  SxV [blocks][texels][C]   (row-major floats)
// rgb: 1 block, row = c + 3 (l + nL v); dfmf: 3 blocks (Y', U/Y, V/Y), row = l + nL v.
// The references compute exactly the kernels' sums in the same order, in float, so kernel and
// reference agree to float rounding (tests assert a relative error <= 1e-5).
#pragma once
#include <memory>
#include <span>
#include <vector>

#include "core/status.h"
#include "kernels/btfc_shared.h"

namespace btfc::fmf_cl {

struct PackedFactors {
  int mode = BTFC_FMF_RGB;
  int blocks = 1, C = 0, rows_per_block = 0, texels = 0, nL = 0, nV = 0;
  float eps = BTFC_DRR_EPS;  // dfmf: the luminance offset (Bonn's colour model 11: BTFC_DRR_EPS)
  // Each block's own components (<= C; the rest of its C columns are zeros): dfmf's chroma blocks
  // are padded to the luminance's C. Empty: C each. The eval and decode kernels stop at them.
  std::vector<int> block_C;
  std::vector<float> U, SxV;
};

// Measured queries are (texel, light, view, unused).
struct MeasuredQuery {
  int texel, light, view, pad;
};

void eval_measured_reference(const PackedFactors& f, std::span<const MeasuredQuery> q, float* out_rgb);
void eval_interp_reference(const PackedFactors& f, std::span<const btfc_fmf_query> q, float* out_rgb);
// One direction pair (the texel field of `pair` is ignored) and many texels: a frame or tile of
// texels under one light and view, the rendering case. rgb mode blends the pair's 9 eigen-ABRDF
// rows once (blend_pair) and then costs one C-length dot per channel and texel; dfmf mode is not
// linear in U (exp per sample) and evaluates like eval_interp.
void eval_pair_reference(const PackedFactors& f, const btfc_fmf_query& pair, std::span<const int> texels, float* out_rgb);
// Ub[c C + k] = sum_ab (wl_a wv_b) U[3 (l_a + nL v_b) + c][k], (a, b) in row-major order, zero
// weights skipped (rgb mode; the kernels use the same order).
void blend_pair(const PackedFactors& f, const btfc_fmf_query& pair, float* Ub);
// A mixed batch: runs of at least k_min_pair_run consecutive queries sharing one direction pair
// go through eval_pair, everything else through eval_interp. Results keep the queries' order.
constexpr size_t k_min_pair_run = 64;
void eval_batch_reference(const PackedFactors& f, std::span<const btfc_fmf_query> q, float* out_rgb);
// Decodes texels `texels` (indices into the model) at direction rows selected by (lights, views):
// out[i][row'] in the layout of core/btf.h for the sub-BTF (row' = c + 3 (l' + nl' v')).
void decode_reference(const PackedFactors& f, std::span<const int> texels, std::span<const int> lights,
                      std::span<const int> views, float* out);

// The factors uploaded to the OpenCL device once, then evaluated / decoded many times.
class DeviceFactors {
 public:
  static Result<std::shared_ptr<DeviceFactors>> upload(const PackedFactors& f);
  ~DeviceFactors();
  Status eval_measured(std::span<const MeasuredQuery> q, float* out_rgb) const;
  Status eval_interp(std::span<const btfc_fmf_query> q, float* out_rgb) const;
  Status eval_pair(const btfc_fmf_query& pair, std::span<const int> texels, float* out_rgb) const;
  Status eval_batch(std::span<const btfc_fmf_query> q, float* out_rgb) const;
  Status decode(std::span<const int> texels, std::span<const int> lights, std::span<const int> views, float* out) const;

  struct Impl;  // device buffers + host copy (fmf_cl.cpp)

 private:
  std::unique_ptr<Impl> m;
};

}  // namespace btfc::fmf_cl
