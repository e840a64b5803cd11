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
  std::vector<float> U, SxV;
};

// Measured queries are (texel, light, view, unused).
struct MeasuredQuery {
  int texel, light, view, pad;
};

void eval_measured_reference(const PackedFactors& f, std::span<const MeasuredQuery> q, float* out_rgb);
void eval_interp_reference(const PackedFactors& f, std::span<const btfc_fmf_query> q, float* out_rgb);
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
  Status decode(std::span<const int> texels, std::span<const int> lights, std::span<const int> views, float* out) const;

  struct Impl;  // device buffers + host copy (fmf_cl.cpp)

 private:
  std::unique_ptr<Impl> m;
};

}  // namespace btfc::fmf_cl
