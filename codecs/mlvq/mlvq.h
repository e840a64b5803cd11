// Codec `mlvq`: multi-level vector quantization with SSIM, scale factors and Huffman-coded indices.
//
// Paper: seed 003, an extension of Havran, Filip and Myszkowski 2010, "Bidirectional texture
// function compression based on multi-level vector quantization", with adaptive colour
// decomposition schemes, Huffman coding of indices and an OpenCL SSIM search
// (Computer Graphics Forum 29(1), 2010; sections 3, 4.1-4.3, 5 of the extension). The MLVQ
// database layout it mirrors is the btfc specification's formats chapter, section 2.5 (PDF1D /
// PDF2D / PDF3D / PDF4D / PDF6D).
//
// Pipeline (mlvq_internal.h has the exact contracts):
//  1. resample.cpp: the four levels' axes. Default layout "measured": level 4 = groups of views,
//     3 = the views of a group, 2 = groups of lights, 1 = the lights of a group (ceil(sqrt(n))
//     per group: 9 x 9 for the 81 UBO2003 directions), over the *measured* values, converted
//     to luminance L = (R+G+B)/3 and chromaticity (r, g) = (R, G) / (R+G+B). Layout "grid" (the
//     paper's): every texel's ABRDF resampled (9-lookup interpolation, core/interp.h) onto a
//     regular 4D grid phi_v x theta_v x alpha x beta (16 x 7 x 11 x 11).
//  2. codebook.cpp: top-down hierarchical VQ (4D -> 3D -> 2D -> 1D). A vector reuses the entry of
//     the level's codebook that matches it best up to a least-squares scale when the SSIM is at
//     least the level's threshold, else it becomes a new entry whose sub-slices go one level down.
//     Luminance and chromaticity are split at level s (scheme s = 1..4) by a merge codebook M of
//     (luminance index, chromaticity index) pairs; above s the codebooks hold RGB slices.
//  3. Scales refitted bottom-up by least squares against the final reconstructions, quantized
//     log-uniformly to 8 bits (LDR) or 10 bits (HDR; 16 when the texels' peaks span > 1e4) and
//     zstd-coded where that is smaller; level-1 values in steps of 2^-8 (zq tensors,
//     core/quant.h) instead of the paper's half floats.
//  4. huffman.cpp: each codebook's index stream is stored bit-packed in the minimal number of
//     bits or canonical-Huffman coded (code table counted), whichever is smaller (section 4.2).
//  5. mlvq_model.cpp: decoding by chained lookups; at measured directions one node (measured
//     layout) or a 4D multilinear blend (grid); arbitrary directions blend the 3 x 3 nearest
//     measured pairs (core/interp.h, measured layout) or the grid; OpenCL batched evaluation
//     (kernels/mlvq.cl, mlvq_cl.cpp).
//
// Why the measured layout is the default (deviation from the paper, issue 22): on measured
// data with narrow highlights (the textile's lurex threads, 15-degree sampling) the resampling
// alone, measured -> 16 x 7 x 11 x 11 grid -> measured, has a relative RMSE of 0.59: the grid
// nodes fall between measured directions and blur highlights that no threshold brings back.
// Over the measured directions there is no resampling error where the data was measured, and
// arbitrary directions are interpolated between measured ones as every other btfc codec does.
// The hierarchy stays the paper's (4 levels, SSIM leader VQ with scales, M split, Huffman
// indices); only what a "slice" contains changes (a group of views / lights instead of an
// angular sub-grid). Giving any of phi / theta / alpha / beta selects the grid (layout=auto).
//
// Default thresholds (0.95 / 0.93 / 0.9 / 0.9 for levels 4..1, noise=auto, chroma=3): the
// paper's profile (0.9 / 0.9 / 0.95 / 0.98) is strictest at the shortest vectors. On noisy data
// that stores the noise: a 9-value level-1 vector of Monte Carlo noise matches no other at
// SSIM 0.98, while a reuse at level 4 or 3 saves a whole subtree (hundreds of values for one
// index and scale). So the defaults are strict at the top and loose at the bottom, and
// noise=auto caps each level at its "noise ceiling" (noise.cpp: the median SSIM two noisy
// copies of one slice reach, from a MAD noise estimate of the data; never more than 0.2 below
// the given threshold, which bounds what a misestimate can do). On the textile only level 1
// binds (ceiling 0.89); on clean data none does. Chromaticity thresholds are 1 - 3 (1 - t):
// chromaticity is scale-free and multiplied by luminance, and in dark values it is mostly noise
// (r, g of near-zero RGB), which at chroma=1 filled a third of the payload. min_ratio=30: when the
// payload still exceeds raw / 30 (very noisy data), all thresholds are relaxed (1 - t) x 1.6
// and the encode repeated (at most 4 times), so the default never gives a tiny ratio.
// Measurements: docs/benchmarks.md, "mlvq on noisy HDR data (issue 22)".
//
// Parameters: scheme (4 by default | best | 1..3), ssim4..ssim1, chroma, layout
// (auto|measured|grid), phi/theta/alpha/beta (grid), value_bits, huffman (auto|off),
// scale_bits (auto|8|10|12|16), noise (auto|off), min_ratio.
//
// Estimator caveat of noise=auto: contrast at the texel scale that repeats in the partner image
// (same light, nearest other view) is taken for texture (noise.cpp), so a speckled albedo no
// longer reads as noise; contrast that does not repeat still does: on a BTF whose texel
// magnitudes jump by 100x between neighbours
// (tests/mlvq_test.cpp HdrFromOneMillionth...) it drives the ceilings towards 0; the 0.2 floor
// keeps the thresholds usable there. `scheme=best` encodes with all four schemes and keeps the
// smallest among those whose estimated quality (mean per-texel SSIM of the luminance) is
// within 0.005 of the best scheme's; the default is scheme 4 (one encode: a quarter of the
// time): chromaticity gets its own small hierarchy, which on the textile is 13 - 95 entries
// per level against thousands for luminance.
#pragma once
#include "codecs/codec.h"

namespace btfc {

const Codec& mlvq_codec();
// Its GPU exporter (codecs/gpu_export.h), defined in mlvq_export.cpp.
namespace gpu {
struct Exporter;
extern const Exporter k_mlvq_exporter;
}  // namespace gpu

}  // namespace btfc
