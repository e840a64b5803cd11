// Codec `lpyr`: Laplacian-pyramid PCA with a Phong-fitted mean and continuous level of detail.
//
// Paper: W.-C. Ma, S.-H. Chao, Y.-T. Tseng, Y.-Y. Chuang, C.-F. Chang, B.-Y. Chen, M. Ouhyoung,
// "Level-of-detail representation of bidirectional texture functions for real-time rendering",
// ACM SIGGRAPH Symposium on Interactive 3D Graphics and Games (I3D) 2005 (sections 3.1-3.4;
// results 4.2).
//
// Model (per colour channel c of YCbCr, level k = 0..lmax, texel p, direction row r = l + nL v):
//   F_0 = the BTF image, F_{k+1} = down(box3 * F_k), L_k = F_k - up(F_{k+1})     (eqs. 2-3)
//   L_k(p, r) ~ sum_j d_kj(p) e_kj(r) [+ mu_k(r)]                                 (eq. 4)
//   F_lmax(p, r) ~ sum_j d_j(p) e_j(r) + mu'(r),  mu'_Y = Phong (eq. 5), mu'_Cb,Cr = const (eq. 6)
//   value(p, r; lambda) = sum_{k >= floor(lambda)} w_k (D_k . E_k [+ mu_k])(p >> k, r) + mu'(r),
//   w_k = clamp(1 - lambda + k, 0, 1), then YCbCr -> RGB                          (eq. 7)
// lambda = 0 is full detail; lambda = k (integer) gives up^k(F_k): the BTF filtered to level k;
// lambda = lmax is the top level (a nearly texture-free BRDF for the default level count).
//
// Exact choices (the paper leaves them open):
//  - Colour: ITU-R BT.601 full range (Kr 0.299, Kb 0.114) on the linear float data, no chroma
//    offset; exact inverse. 3-channel BTFs only.
//  - Odd sizes: w_{k+1} = ceil(w_k / 2); box3 uses clamped (replicated) borders and is sampled at
//    even coordinates; up-sampling is nearest neighbour, texel (x, y) of level k reads
//    (x / 2, y / 2) of level k + 1 (the extra last row/column is cropped). So level k of any
//    level-0 texel is (x >> k, y >> k). 1x1 BTFs have lmax = 0 (plain PCA with mean).
//  - Levels from the data (`levels=0`; issue 22 "defaults that fit the data"). Bytes: level k
//    of N_k = w_k h_k texels stores per PCA component a basis of d values (d = nL nV, 6561 for
//    UBO2003) and N_k weights, y + 2c components. Its bases cost d / N_k times its weights,
//    whatever the counts, and on coarse levels (N_k << d) they are nearly all its bytes while the
//    level adds little: on synthetic 81 x 81 BTFs of 16, 48, 64, 96 texels square and on the
//    textile, the levels with d > 64 N_k cost 24-62 % of the paper's payload and bought at most
//    0.5 dB (0.02 dB from 48 x 48 up; docs/benchmarks.md). Rule: lmax = the paper's stop (the
//    first k with w_k h_k <= 2 y, capped where the level becomes 1x1) or earlier, the largest k
//    such that every level j <= k has d <= basis_ratio N_j (its bases cost at most basis_ratio =
//    64 times its weights); 0 when level 0 already fails. 81 x 81 directions: the top level has
//    >= 103 texels (64 x 64 -> lmax 2 where the paper has 4; 16 x 16 -> plain PCA); a single
//    view (d = 81) keeps the paper's levels. Ratio (float32 raw, 12 N_0 d bytes): the bases are
//    2 (lmax + 1) (y + 2c) d bytes, i.e. 1:(N_0 / (2 (lmax + 1))) at 8 / 2 / 2, the weights add
//    1:2460 and a stored mean 1:N_0 per channel (f32), so any full 81 x 81 BTF of 48 x 48 texels
//    or more (lmax <= log4(N_0 / 103) + 1) stays above 1:200; measured 1:83 at 16 x 16, 1:291 at
//    48 x 48, 1:474 at 64 x 64, 1:724 at 96 x 96 (the paper's rule: 1:32, 1:193, 1:307, 1:550).
//    The per-level counts stay the paper's y / c: fewer components on small levels (tried: at
//    most one per 16..256 texels, or bases at most 1..16 x the weights) lost 0.5-8 dB and most of
//    the SSIM for 25-170 % more ratio, worse than fmf's rank trade on the same data.
//    The used levels go into the model's spec (levels=0 resolved to lmax + 1). basis_ratio=0 is
//    the paper's rule alone (64x64, y=8 -> lmax 4). `levels=n` asks for lmax = n - 1 (capped
//    where the level becomes 1x1; the clamp is noted in the stats).
//  - PCA per level and channel: fmf's truncated SVD (core/svd.h) of the d x N_k matrix
//    (d = nL nV directions, N_k texels): exact Gram eigen-decomposition on the small side when
//    min(d, N_k) <= 256, else randomized range finder (GEMM passes; 16 oversampling columns,
//    4 power iterations, seeded by Context::seed). Components: y for Y, c for Cb and Cr, clamped
//    to the data's numerical rank.
//  - Laplacian means (`laplacian_mean`): the paper drops them (their expectation is zero). We
//    measure each level's mean energy fraction f = N_k |mu_k|^2 / |L_k|^2; `auto` keeps the mean
//    (d floats, f32) when f > 1e-2, i.e. when it carries more than 1 % of the level's energy
//    (the textured synthetic and measured data give f ~ 1e-4 .. 1e-3: dropped). Reported per level.
//  - Top mean (`mean`): the mean is computed, the Y mean fitted by Phong (Ceres LM, see
//    lpyr_internal.h), Cb/Cr by their averages. `phong` uses the fit, `stored` stores the three
//    mean vectors (f32), `auto` uses Phong unless its relative residual |mu_Y - phong| / |mu_Y|
//    exceeds 0.1 (a material Phong cannot describe); the stats report the residuals and the
//    choice. The top level's PCA is computed on F_lmax minus the *chosen* mean, so with Phong
//    the components also absorb the systematic part of the Phong misfit.
//
// Stored tensors (precision=half: E and D in f16, D divided per component by scale; else f32):
//   levels        u32 [lmax+1, 6]  per level: w, h, C_y, C_cb, C_cr, flags (bit c: mean of
//                                  channel c stored; bit 3: top mean is Phong)
//   E.<k>.<ch>    [d, C]           eigen-Laplacian-BRDFs, ch in y, cb, cr
//   D.<k>.<ch>    [N_k, C]         PCA weights / scale
//   scale.<k>.<ch> f32 [C]
//   mean.<k>.<ch>  f32 [d]         only when its flag is set
//   phong         f32 [6]          ka, kd, ks, alpha, Cb constant, Cr constant (Phong top only)
// precision=q (same payload version; the spec says which): E.<k>.<ch> and D.<k>.<ch> are zq
// tensors (core/quant.h) of the same shapes, mean.<k>.<ch> a zq [d, 1], no scale tensors.
// Steps, equal squared error per stored value in the decoded RGB BTF at lod 0 (as fmf's
// precision=q, codecs/fmf/fmf_quant.h): level k's texel covers n_0 / N_k level-0 texels, and a
// unit change of channel ch changes RGB by a squared amount g_ch (the inverse YCbCr matrix's
// column: 3 for Y, about 3.26 for Cb and 2.47 for Cr). E has orthonormal columns, so a weight
// rounded with step e adds e^2 / 12 x n_0 / N_k x g_ch; an entry of E_j with step s adds
// s^2 / 12 x ||D_j||^2 n_0 / N_k g_ch; a mean entry with step m adds m^2 / 12 x n_0 g_ch. With
// R = 2^-bits x the RMS over texels of the RGB ABRDF norm (`bits` about the bit depth of the
// strongest weight, as fmf's bits; over lights x views / 16 "texels" when there are fewer, as
// fmf's D, else a few texels' means would take most of the error):
//   D step  e = R / sqrt(g_ch n_0 / N_k),  E_j step e / ||D_j|| (at most 4),  mean step R / sqrt(g_ch n_0).
// Means are quantized before their level's PCA (which absorbs their rounding); Phong stays f32.
// The model holds the dequantized values (in memory = file), so exports read floats.
//
// GPU tensors (paper section 3.3; need y <= 8 and c <= 2, missing components are zero):
//   eigen_map      f32 [(lmax+1) nV, 3 nL, 4]: RGBA texel (row k nV + v, column j nL + l) holds
//                  slot j of level k at light l, view v: j=0 Y e1..e4, j=1 Y e5..e8,
//                  j=2 (Cb e1, Cb e2, Cr e1, Cr e2). 3p x (lmax+1)q for p = nL, q = nV.
//   weight_map     f32 [H2, W2, 4]: level k's three slots (same j order, RGBA = the matching
//                  weights d_kj) are w_k x h_k images at (ox_k, oy_k), (ox_k + w_k, oy_k) and
//                  (ox_k, oy_k + h_k), with (ox_0, oy_0) = (0, 0), (ox_{k+1}, oy_{k+1}) =
//                  (ox_k + w_k, oy_k + h_k): each level nests in the previous one's fourth
//                  quadrant. W2 = max_k ox_k + 2 w_k (= 2r for r x r, r a power of two), rows
//                  are texel rows y (row 0 = y 0). Unused texels are 0.
//   mean_map       f32 [(lmax+1) nV, nL, 4]: (Y, Cb, Cr, 0) mean added at level k (zero for
//                  dropped Laplacian means; the top row block is the evaluated top mean mu').
//   phong          f32 [6]  ka, kd, ks, alpha, Cb, Cr (only when the top mean is Phong)
//   direction_lut  u32 [2, 32, 32]: nearest measured light (plane 0) / view (plane 1) index for
//                  the parabolic coordinate p = (-1 + (j + 0.5) / 16, -1 + (i + 0.5) / 16)
//                  at row i, column j (p outside the unit disc is moved onto its rim).
//   A renderer evaluates eq. 7 with D from weight_map at (p >> k) in level k's slots, E from
//   eigen_map at the LUT's (l, v), adds w_k mean_map (or Phong for the top), then YCbCr -> RGB.
//
// Parameters: levels (0 auto), y (8), c (2), basis_ratio (64), mean (auto|phong|stored),
// laplacian_mean (auto|keep|drop), precision (half|float|q), bits (8). See the table in lpyr.cpp
// for ranges.
#pragma once
#include "codecs/codec.h"

namespace btfc {

const Codec& lpyr_codec();
// Its GPU exporter (codecs/gpu_export.h), defined in lpyr_export.cpp.
namespace gpu {
struct Exporter;
extern const Exporter k_lpyr_exporter;
}  // namespace gpu

}  // namespace btfc
