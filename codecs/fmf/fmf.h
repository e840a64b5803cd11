// Codec `fmf`: full matrix factorization (truncated SVD) of the BTF matrix.
//
// Paper: C. Schwartz, R. Ruiters, R. Klein, "Level-of-Detail Streaming and Rendering using
// Bidirectional Sparse Virtual Texture Functions", Computer Graphics Forum 32(7), Pacific
// Graphics 2013 (section 4, full matrix factorization; the BSVTF of its sections 5-7 is
// formats/bsvtf/):
// B = U Sigma V^T truncated after C columns, V := V Sigma, rho(x, wl, wv) ~ sum_c U_c(wl, wv) V_c(x),
// arbitrary directions by Delaunay triangulation of each direction set in parabolic coordinates
// with barycentric weights (9 lookups).
//
// Colour (`color=`):
//   rgb  - colour inside the matrix rows, as in the paper: one factorization of the
//          (view, light, colour) x texel matrix; the matrix is the Btf buffer itself (no copy).
//   dfmf - per-channel decorrelated factorization in the form of Bonn's DFMF colour model 11
//          (formats.md 2.2, "Ylog_UdivY_VdivY"): YUV, then Y' = log(Y + e), U' = U / (Y + e),
//          V' = V / (Y + e); each of Y', U', V' is factorized separately ((view, light) x
//          texel), Y' with `rank` and the chroma with `chroma_rank` components. Decoding
//          inverts exactly that. Negative luminance (HDR noise) is clamped to 0 (counted).
//          The offset e (`offset`; 0 = from the data): Bonn fixes e = 1e-5, which makes the
//          SVD's objective the error of log(Y) down to 1e-5: on HDR data it spends the rank on
//          the logarithms of near-black values and lets the highlights, which hold the data's
//          energy, carry log errors that exp() turns into errors of the size of the data
//          (docs/benchmarks.md, "dfmf on HDR data"). A factorization error d of Y' or U' costs
//          (Y + e) d in the data, so e sets where the model is relative (Y >> e, log-like) and
//          where absolute (Y << e). The default e = sum Y^2 / sum Y (the energy-weighted mean
//          luminance, over a sample of up to 4096 evenly spaced texels: dfmf_offset_sample)
//          puts the bright values that hold the L2 energy on the absolute side; it scales with
//          the data (a BTF times s gives the same model, offset times s). The model's
//          spec holds the resolved e. Only e = 1e-5 is Bonn's colour model 11 exactly: the Bonn
//          DFMF writer and the OpenCL kernels take those models only (other offsets decode on
//          the CPU path; write them as .btfc).
//          target_error is the relative L2 error of the decoded data against the input: the
//          channels are factorized at rank / chroma_rank, then truncated to the smallest luminance
//          rank (chroma ranks scaled alike) that meets it (in core only).
//
// Storage per factorized block b ("rgb" or "y", "u", "v"):
//   U.<b>     [rows, C]   f16 or f32   eigen-ABRDFs, orthonormal columns (|entry| <= 1)
//   SxV.<b>   [texels, C] f16 or f32   eigen-textures divided by scale.<b> (so |entry| <= 1:
//                                      half storage cannot overflow whatever the HDR range)
//   scale.<b> [C]         f32          per-component scale of SxV (max |SxV_c|)
//   S.<b>     [C]         f32          singular values (informational, like Bonn's files)
// Rows are (light fastest, then view; rgb: colour fastest) exactly as core/btf.h and Bonn FMF/DFMF.
//
// precision=q (codecs/fmf/fmf_quant.h): U.<b> and SxV.<b> are zq tensors (core/quant.h:
// per-component integers and steps, zstd-coded; textures=dct codes the SxV columns as 8 x 8 DCT
// coefficients of the width x height eigen-texture images), scale.<b> is all ones. The steps
// give every component the same squared error: SxV step D = 2^-bits x RMS of the strongest
// eigen-texture, U column k step D / sigma_k. payload_bytes() is the tensors' real size.
#pragma once
#include <memory>
#include <string>
#include <vector>

#include "codecs/codec.h"
#include "codecs/gpu_export.h"

namespace btfc {

const Codec& fmf_codec();
// Its GPU exporter (codecs/gpu_export.h), defined in fmf_export.cpp.
namespace gpu {
struct Exporter;
extern const Exporter k_fmf_exporter;
}  // namespace gpu

// ---- Bonn DFMF / FMF files as fmf models (formats/bonn/bonn_btf.h, formats.md 2.2) ----
//
// A Bonn file already is a factorization, so it becomes an fmf model without re-encoding.
// Per factorized block: U [rows x C] and SxV [texels x C], row-major, SxV = V * Sigma.
struct FmfFactors {
  std::string name;          // "rgb" (one block, rows = nC*nL*nV) or "y","u","v" (rows = nL*nV)
  std::vector<float> U;      // rows x C, row-major
  std::vector<float> SxV;    // texels x C, row-major
  std::vector<float> S;      // C singular values (informational)
  int C = 0;
};

// Bonn colour models (formats.md 2.2 table) the fmf decoder inverts. One "rgb" block:
// 0 (plain) or 12 (value = exp(v) - 1e-5, FMF dynamic range reduction). Three per-channel
// blocks (DFMF): 0, 1, 3, 4, 9, 10, 11, 12. Others (2 Lab, 5/6 spectral) answer unsupported.
// `color_mean` / `color_transform` (row-major, rgb_j = sum_i v_i T[i][j] + mean_j) are used by
// model 3 only. `half`: the precision used when the model is saved to .btfc.
// The model's spec is the equivalent fmf spec ("fmf:color=dfmf:..." for 11, "color=rgb" for one
// block with model 0), so it saves to .btfc; other colour models cannot be saved to .btfc
// (save() answers unsupported) but decode, eval and re-compress normally.
// `dfmf_offset`: the luminance offset e of per-channel blocks in colour model 11 (Bonn files:
// 1e-5; a cut of a btfc dfmf model whose e came from the data: that e).
Result<std::unique_ptr<Model>> make_fmf_model(const BtfDesc& desc, int bonn_color_model, std::vector<FmfFactors> blocks,
                                              const float color_mean[3], const float color_transform[3][3], bool half,
                                              float dfmf_offset = 1e-5f);

// Read-only view of an fmf model's factors, valid while the model lives (for the Bonn writers).
struct FmfBlockView {
  std::string name;
  const float* U = nullptr;    // rows x C row-major
  const float* SxV = nullptr;  // texels x C row-major, dequantized (the values the model decodes)
  const float* S = nullptr;    // C
  size_t rows = 0, texels = 0;
  int C = 0;
};
struct FmfFactorsView {
  bool per_channel = false;  // true: blocks y,u,v (DFMF layout); false: one "rgb" block (FMF layout)
  int bonn_color_model = 0;  // 11 for color=dfmf, 0 for color=rgb; as given to make_fmf_model otherwise
  bool half = true;
  float drr_eps = 1e-5f;     // the luminance offset e of color=dfmf (Bonn's model 11: 1e-5)
  float color_mean[3] = {0, 0, 0};
  float color_transform[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  std::vector<FmfBlockView> blocks;
};
// invalid_argument when `model` is not an fmf model.
Result<FmfFactorsView> fmf_factors(const Model& model);

// An fmf model (color=rgb) from a finished factorization of the BTF matrix, as encode() makes it
// (quantisation to the spec's precision, rank / error statistics); for the out-of-core path
// (codecs/fmf/ooc_fmf.h), whose SVD streams. `r.SxV` must hold all texels.
struct SvdResult;
Result<std::unique_ptr<Model>> make_fmf_model_from_svd(const BtfDesc& desc, const Params& params, SvdResult r, ModelStats stats);
// The same for color=dfmf from the factorizations of the three channel matrices (rows =
// num_images, see dfmf_channel): y with at most `rank`, u and v with `chroma_rank` (or rank).
Result<std::unique_ptr<Model>> make_dfmf_model_from_svd(const BtfDesc& desc, const Params& params, SvdResult y, SvdResult u,
                                                        SvdResult v, ModelStats stats);

// color=dfmf's colour transform of one texel: from its ABRDF `abrdf` (rows = num_images RGB
// triples, the Btf layout) writes channel k (0: Y' = log(Y + e), 1: U' = U / (Y + e),
// 2: V' = V / (Y + e); YUV of Bonn's colour model 11, e = `offset`) to out[0, rows). Negative
// luminance (HDR noise) is clamped to 0; returns how many of the rows were clamped (the same for
// every k). The one definition both the in-core encode and the streamed one (ooc_dfmf.h) use,
// so the two factorize the same matrices.
size_t dfmf_channel(const float* abrdf, size_t rows, int k, float offset, float* out);
// All three channels at once (y, u, v: rows floats each), vectorized; dfmf_channel returns the
// same bits. Y' = log is computed by a polynomial within 2e-7 relative of std::log (std::log
// itself for sums that are not normal finite floats).
size_t dfmf_channels(const float* abrdf, size_t rows, float offset, float* y, float* u, float* v);
// The automatic offset (offset=0): adds one texel's sum of Y and of Y^2 (Y clamped to >= 0) to
// *sum_y, *sum_y2; dfmf_auto_offset turns sums into e = sum Y^2 / sum Y (Bonn's 1e-5 when there
// is no luminance; at least the smallest normal float). Returns true when a luminance was NaN or
// inf: whenever a value is, and for finite values only if their weighted sum rounds past the
// largest float (the Y weights are positive and sum to 1).
bool dfmf_luminance_moments(const float* abrdf, size_t rows, double* sum_y, double* sum_y2);
double dfmf_auto_offset(double sum_y, double sum_y2);
// The offset parameter's ceiling, and the automatic offset's: the largest float, as its 9-digit
// spelling in a spec (3.4028234e38 rounds to FLT_MAX) stays within it. Not lower, so that e
// scales with any finite data (the encode of a BTF times s is that of the BTF, e times s).
constexpr double k_dfmf_max_offset = 3.4028234e38;
// The texels the automatic offset is taken from: m = min(texels, 4096) evenly spaced ones,
// texel i x texels / m (integer division) for i < m, increasing. e is a scale (the data's
// energy-weighted mean luminance), which a few thousand texels give to a fraction of a percent
// (+0.6 % on the UBO2003-size synthetic BTF); summing every texel cost the in-core encode a read
// of the whole BTF before its first pass (0.13-0.15 s of 2.2 s at that size). Out of core the
// offset's sweep stays: it is also every chunk's first sight (ooc_dfmf.h).
std::vector<size_t> dfmf_offset_sample(size_t texels);
// e from the sample's sums: sums[2 i], sums[2 i + 1] = sample texel i's sum Y and sum Y^2, each
// from zero (dfmf_luminance_moments), added in sample order. Every encode path (in core, out of
// core, any number of MPI processes) fills the same table this way, so all pick the same bits.
double dfmf_offset_from_sample(const std::vector<double>& sums);
// The automatic offset of an in-memory BTF of 3 channels (the in-core encode's).
double dfmf_auto_offset(const Btf& btf);
// The portable builds of the two loops above, which this CPU's kernels (AVX2 or AVX-512) are
// tested against: dfmf_channels returns their bits, dfmf_luminance_moments their sums to
// rounding (its lanes add in another order).
size_t dfmf_channels_reference(const float* abrdf, size_t rows, float offset, float* y, float* u, float* v);
bool dfmf_luminance_moments_reference(const float* abrdf, size_t rows, double* sum_y, double* sum_y2);
// For tests: the AVX2 kernels of the two on any CPU with AVX2 + FMA (an AVX-512 CPU runs its own
// otherwise, so they would go untested there). False where they do not apply (nothing written);
// else *clamped / *bad get what dfmf_channels / dfmf_luminance_moments return.
bool dfmf_channels_avx2(const float* abrdf, size_t rows, float offset, float* y, float* u, float* v, size_t* clamped);
bool dfmf_luminance_moments_avx2(const float* abrdf, size_t rows, double* sum_y, double* sum_y2, bool* bad);
// `p` (a color=dfmf fmf spec) with offset = `offset`: the spec a model of that offset carries.
Result<Params> dfmf_with_offset(const Params& p, double offset);

namespace gpu {

// The fmf model restricted to what `opt.scene` needs, as the KTX2 export keeps it: eigen-textures
// box-filtered to the finest mip level the scene samples, the kept components, and the measured
// directions inside the (widened) cones. Without a scene (or a scene that keeps everything) it
// is the model itself. model.bsvtf of a scene export is built from it, so the streaming file
// holds only the scene's tiles, levels and packets.
Result<std::unique_ptr<Model>> fmf_scene_model(const Model& fmf_model, const ExportOptions& opt);

}  // namespace gpu

}  // namespace btfc
