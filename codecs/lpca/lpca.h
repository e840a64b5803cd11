// Codec `lpca`: local (clustered) PCA of per-texel ABRDFs, spherical-harmonic projection of
// the eigen-BRDFs, environment relighting and precomputed radiance transfer (PRT).
//
// Paper: G. Müller, J. Meseth, R. Klein, "Fast Environmental Lighting for Local-PCA Encoded BTFs",
// Computer Graphics International 2004 (sections 3-5;
// the seed text carries no title line, the attribution follows its abstract and content):
//   B_x ~ mean_k(x) + sum_{i=1..c_B} <B_x - mean_k(x), E_{i,k(x)}> E_{i,k(x)}   (section 3)
// with k(x) the texel's cluster (clustering.h: k-means++ seeding, then {PCA per cluster,
// reassignment by reconstruction error}); each eigen-BRDF (mean included) is projected per view
// and colour onto real SH over the light hemisphere (order n, n^2 coefficients; quadrature over
// the measured light directions weighted by their Voronoi cell's solid angle; the data already
// contains the cosine factor), so relighting a texel under an SH environment a is
//   L_r(x, v) = sum_{m=0..c_B} beta_{x,m} <e^v_{m,k(x)}, M a>          (eq. 2, 3; beta_0 = 1)
// with M the SH rotation from world into the sample frame.
//
// Stored tensors (payload version 1):
//   cluster       [H, W]          u16      cluster index k(x) in [0, K)
//   table         [K, c+1, rows]  f16|f32  per cluster: mean / mean_scale[k], then c eigen-BRDFs
//                                          (orthonormal, |entry| <= 1; zero rows when a cluster's
//                                          rank is lower); rows in core/btf.h order
//   mean_scale    [K]             f32      max |mean| per cluster (1 for float storage)
//   weights       [H, W, c]       f16|f32  PCA weights / weight_scale[k(x), i]
//   weight_scale  [K, c]          f32      max |weight| per (cluster, component) (1 for float)
// Half storage cannot overflow whatever the HDR range: every stored value is within [-1, 1].
// precision=q ("bits where they matter", same payload version; the spec says which layout):
//   cluster       [H, W, 1]       zq       the cluster index, step 1 (exact; zstd codes its entropy)
//   table         [rows, K (c+1)] zq       column k (c+1) + m = cluster k's mean (m = 0) or
//                                          eigen-BRDF m, each column with its own step
//   weights       [H, W, c]       zq       PCA weights, one step D for every column
// (no scale tensors). Steps, equal squared error per stored value (the rate-distortion optimum
// at high rate, as fmf's precision=q, codecs/fmf/fmf_quant.h): a texel is
// mean_k + sum_i w_i E_ki with orthonormal E_ki, so rounding a weight with step D adds D^2 / 12
// to ||B - B~||^2, rounding an entry of E_ki with step d adds d^2 / 12 sigma_ki^2 (sigma_ki^2 =
// sum of w_i^2 over the cluster's members) and one of the mean adds d^2 / 12 n_k (n_k members).
// Hence weight step D, eigen-BRDF step D / sigma_ki (at most 4: a component without energy
// rounds to zero), mean step D / sqrt(n_k), with D = 2^-bits x the RMS over texels of the
// ABRDF norm ||B_x|| (so `bits` is about the bit depth of the strongest weight, as fmf's bits;
// every setting follows the data's scale). With fewer texels than abrdf_size / 16 (a few texels
// under many directions) the RMS is taken over abrdf_size / 16 "texels", as fmf's D: the table's
// share of the error would otherwise be abrdf_size / texels times the weights'. The table is quantized first and the weights are
// projected onto the dequantized table, so they absorb its rounding. The model holds the
// dequantized values: in memory it equals the file bit for bit, and exports read floats.
// The SH coefficients are derived from the table at load (cheap: K(c+1) x views x lights x n^2),
// so they cost no storage; sh_order only sets their order.
//
// Frames: the sample lies in its tangent frame (z = normal, x = the direction sets' phi = 0).
// Environments are given in world coordinates; `sample_to_world` (default identity) maps sample
// to world vectors. A lat-long map's pixel (i, j) of W x H covers theta (from world +z, row 0 at
// the zenith) in [pi j/H, pi (j+1)/H] and phi (from +x towards +y) in [2 pi i/W, 2 pi (i+1)/W].
#pragma once
#include <string>
#include <vector>

#include "codecs/codec.h"
#include "core/sh.h"

namespace btfc {

const Codec& lpca_codec();
// Its GPU exporter (codecs/gpu_export.h), defined in lpca_export.cpp.
namespace gpu {
struct Exporter;
extern const Exporter k_lpca_exporter;
}  // namespace gpu

struct RelightOptions {
  sh::Mat3 sample_to_world;  // the sample's frame in the world; identity = lying flat, z up
};

// Renders the flat sample under `env` (world frame) seen from `view_dir` (world frame, pointing
// from the sample to the viewer): one RGB float triple per texel, row-major, w x h = the BTF's
// texels. Views between the measured ones are interpolated (parabolic Delaunay). Uses
// min(env order, the model's sh_order) bands. Errors: not an lpca model, view below the
// sample's horizon, empty environment. Single-channel BTFs are replicated to grey.
Result<std::vector<float>> relight(const Model& lpca_model, const EnvironmentSH& env, const Vec3& view_dir, int& w,
                                   int& h, const RelightOptions& opt = {});

// PRT for a fixed lighting (seed 002 section 5.1): lambda[k][m][view] = <e^v_{m,k}, M a> per colour
// channel, resampled over view directions into 16 x 16 parabolic maps (texel (i, j) is the
// direction with parabolic coordinates p = ((i+0.5)/8 - 1, (j+0.5)/8 - 1), clamped to the unit disc;
// values interpolated between measured views) and quantized to 8 bits as
// lambda ~ (q / 127.5 - 1) * scale[category]. The paper's four categories are (m = 0 | m != 0) x
// (transfer component j = 0 | j != 0); a flat sample has no transfer-matrix LPCA (only j = 0), so
// two scales are used: scale[0] for the means (m = 0), scale[1] for the eigen-BRDFs (m != 0).
// Tensors: prt u8 [K, c+1, 16, 16, channels], prt_scale f32 [2], plus cluster_index u16 [H, W] and
// weights f32 [H, W, c], i.e. everything a fragment shader needs (eq. 3).
Result<std::vector<Tensor>> prt_tensors(const Model& lpca_model, const EnvironmentSH& env, const RelightOptions& opt = {});
// Stores prt_tensors(env) in the model, so its gpu_tensors() include them (exporters).
Status attach_environment(Model& lpca_model, const EnvironmentSH& env, const RelightOptions& opt = {});

}  // namespace btfc
