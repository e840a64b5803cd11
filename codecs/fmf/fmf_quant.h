// fmf precision=q: the factors as per-component quantized integers, zstd-coded (core/quant.h's
// zq tensors), with the step sizes chosen so that every component adds the same squared error.
//
// Why these steps ("bits where they matter", reverse water-filling). With U orthonormal and
// SxV = V Sigma, the BTF matrix is B ~ U SxV^T. Rounding column k of U with step d_k adds
// about d_k^2 / 12 per entry, i.e. rows * d_k^2 / 12 * sigma_k^2 to ||B - B~||^2 (sigma_k =
// ||SxV_k||); rounding column k of SxV with step e_k adds texels * e_k^2 / 12 (||U_k|| = 1).
// Equal error per stored value, the rate-distortion optimum at high rate, is therefore
//     e_k = D for every eigen-texture,   d_k = D / sigma_k for the eigen-ABRDFs,
// and components whose entries are smaller than D round (mostly) to zero and cost almost no
// bits: the "water level" D decides which components are worth bits. One knob sets D:
//     D = 2^-bits * sigma_1 / sqrt(max(texels, rows / 16))   (the RMS of the strongest eigen-texture),
// so `bits` is about the bit depth of the strongest eigen-texture, and every setting adapts to
// the data's scale. (rows / 16: with many more rows than texels, a few texels under many
// directions, U's error, rows / texels times SxV's, would otherwise swamp the model.) A step is
// never below max|column| / 2^29 (integers stay in range).
//
// color=dfmf's Y' = log(Y + e) takes sigma_1 without the block's mean (`centred`):
//     sigma_1' = max(sqrt(sigma_1^2 - rows texels m^2), sigma_2),   m = the mean of U SxV^T.
// A BTF times s has Y' + log s, a constant that lands in the strongest component and, through
// sigma_1, in D, though an error in Y' is a relative error of Y at any s: with sigma_1 a synthetic
// 16 x 16 BTF at bits 8 erred 0.17 (relative L2) at s = 1 and 0.46-0.50 at 1e6 and 1e-6. Even at
// s = 1 the mean of log(Y + e) set Y''s steps, too coarse: byte budgets of 150 and 400 kB got
// 1.6-3.9 dB more with sigma_1' on the real UBO2003 slice and the textile (docs/benchmarks.md,
// "Bits where they matter").
//
// textures=dct: each SxV column (an image of width x height texels) is coded as its orthonormal
// 8 x 8 DCT (the BSVTF tile transform, core/dct.h) with the same step D: the transform is
// orthonormal, so the error per step is unchanged, and smooth eigen-textures put their energy
// in few coefficients.
#pragma once
#include <string>
#include <vector>

#include "core/svd.h"
#include "core/container.h"

namespace btfc::fmf {

struct QuantConfig {
  int bits = 0;      // 0: not quantized (half / float)
  bool dct = false;  // textures=dct
  bool centred = false;  // D from sigma_1 without the block's mean (color=dfmf's Y', above)
};

struct QuantizedFactors {
  MatrixXfR U, SxV;            // the values the coded tensors decode to (bit for bit)
  std::vector<Tensor> coded;   // zq tensors "U.<name>" [rows, C] and "SxV.<name>" [texels, C]
  Status status;               // not ok: coding failed (U / SxV then hold the input)
};

// Steps of the rule above (first U's C steps, then SxV's C steps).
void quant_steps(const MatrixXfR& U, const MatrixXfR& SxV, int bits, std::vector<float>& u_steps, std::vector<float>& sxv_steps,
                 bool centred = false);

QuantizedFactors quantize_factors(const std::string& name, const MatrixXfR& U, const MatrixXfR& SxV, const QuantConfig& cfg, int width,
                                  int height);

}  // namespace btfc::fmf
