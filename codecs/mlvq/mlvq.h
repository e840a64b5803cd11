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
//  1. resample.cpp: every texel's ABRDF is resampled (9-lookup interpolation between measured
//     directions, core/interp.h) onto a regular 4D grid phi_v x theta_v x alpha x beta
//     (default 16 x 7 x 11 x 11, the paper's) and converted to luminance L = (R+G+B)/3 and
//     chromaticity (r, g) = (R, G) / (R+G+B).
//  2. codebook.cpp: top-down hierarchical VQ (4D -> 3D -> 2D -> 1D). A vector reuses the entry of
//     the level's codebook that matches it best up to a least-squares scale when the SSIM is at
//     least the level's threshold, else it becomes a new entry whose sub-slices go one level down.
//     Luminance and chromaticity are split at level s (scheme s = 1..4) by a merge codebook M of
//     (luminance index, chromaticity index) pairs; above s the codebooks hold RGB slices.
//  3. Scales refitted bottom-up by least squares against the final reconstructions, quantized
//     log-uniformly to 8 bits (LDR) or 16 bits (HDR, detected from the data range).
//  4. huffman.cpp: each codebook's index stream is stored bit-packed in the minimal number of
//     bits or canonical-Huffman coded (code table counted), whichever is smaller (section 4.2).
//  5. mlvq_model.cpp: decoding by chained lookups with 4D multilinear interpolation, at measured
//     or arbitrary directions; OpenCL batched evaluation (kernels/mlvq.cl, mlvq_cl.cpp).
//
// Parameters: scheme (best|1|2|3|4), ssim4..ssim1 (per-level thresholds), phi/theta/alpha/beta
// (grid), huffman (auto|off), scale_bits (auto|8|16), noise (off|auto).
//
// noise=auto (noise.cpp): each level's luminance and chromaticity thresholds are capped at the
// level's "noise ceiling", the median over the level's slices of the SSIM two noisy copies of
// one slice reach, (2 s2 + C2) / (2 s2 + 2 n2 + C2), with the noise variance n2 estimated per
// image by Donoho's MAD of the finest diagonal Haar details and carried through the resampling
// weights. It is off by default because the image-domain estimator counts spatial contrast at
// the texel scale as noise: on a BTF whose texel magnitudes jump by 100x between neighbours
// (tests/mlvq_test.cpp HdrFromOneMillionth...) it drives the ceilings towards 0 and the
// error up to 0.90; and on the textile at the paper's grid the ceilings are 0.98-0.998, i.e.
// they do not bind: noise is not what makes mlvq's codebooks large there (docs/benchmarks.md,
// issue 22 section). `scheme=best` encodes with all four
// schemes and keeps the smallest among those whose estimated quality (mean per-texel SSIM of
// the resampled luminance) is within 0.005 of the best scheme's.
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
