// Codec `fmf`: full matrix factorization (truncated SVD) of the BTF matrix.
//
// Paper: Schwartz, Sarlette, Weinmann, Rump, Klein, "Design and Implementation of Practical
// Bidirectional Texture Function Measurement Devices focusing on the Developments at the
// University of Bonn" / the BSVTF paper (../shared/seeds/000_e242933b2e836b65.txt, section 4):
// B = U Sigma V^T truncated after C columns, V := V Sigma, rho(x, wl, wv) ~ sum_c U_c(wl, wv) V_c(x),
// arbitrary directions by Delaunay triangulation of each direction set in parabolic coordinates
// with barycentric weights (9 lookups).
//
// Colour (`color=`):
//   rgb  - colour inside the matrix rows, as in the paper: one factorization of the
//          (view, light, colour) x texel matrix; the matrix is the Btf buffer itself (no copy).
//   dfmf - per-channel decorrelated factorization as Bonn's DFMF colour model 11
//          (formats.md 2.2, "Ylog_UdivY_VdivY"): YUV, then Y' = log(Y + eps), U' = U / (Y + eps),
//          V' = V / (Y + eps) with eps = 1e-5; each of Y', U', V' is factorized separately
//          ((view, light) x texel), Y' with `rank` and the chroma with `chroma_rank` components.
//          Decoding inverts exactly that. Handles HDR dynamic range well (log luminance).
//          Negative luminance (noise in HDR data) is clamped to 0 and counted in the stats.
//
// Storage per factorized block b ("rgb" or "y", "u", "v"):
//   U.<b>     [rows, C]   f16 or f32   eigen-ABRDFs, orthonormal columns (|entry| <= 1)
//   SxV.<b>   [texels, C] f16 or f32   eigen-textures divided by scale.<b> (so |entry| <= 1:
//                                      half storage cannot overflow whatever the HDR range)
//   scale.<b> [C]         f32          per-component scale of SxV (max |SxV_c|)
//   S.<b>     [C]         f32          singular values (informational, like Bonn's files)
// Rows are (light fastest, then view; rgb: colour fastest) exactly as core/btf.h and Bonn FMF/DFMF.
#pragma once
#include "codecs/codec.h"

namespace btfc {

const Codec& fmf_codec();

}  // namespace btfc
