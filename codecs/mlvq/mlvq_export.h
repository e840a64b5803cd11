// mlvq GPU export, shared between mlvq_export.cpp (textures, manifest) and mlvq_export_glsl.cpp
// (the reference shader and its CPU emulation). Not public API: codecs/gpu_export.h is.
//
// What the renderer of seed 003 (section 3, "chained indexing from the existing codebooks, with
// necessary interpolation among data vectors") reads, as textures (nearest, texelFetch):
//   texel_index   W x H    r16_uint / r32_uint  the texel's level-4 entry (rgb4, or merge if s = 4)
//   texel_scale   W x H    r16f / r32f          the texel's scale factor
//   <part><k>_index        1D array, K_k * n_k  child of entry e at coordinate c: [e n_k + c]
//   <part><k>_scale        1D array, K_k * n_k  its scale (rgb and lum; chromaticity is scale-free)
//                          part = rgb for levels k > s, lum / chroma for 2 <= k <= s
//   merge         1D array, |M| entries, rg16_uint / rgba32_uint: (lum index, chroma index)
//   lum1          1D array, K * nbeta, r16f / r32f      level-1 luminance vectors
//   chroma1       1D array, K * nbeta, rg16f / rg32f    level-1 chromaticity (r, g) vectors
//   measured_coord  nL x nV rgba32f: grid coordinates (phi, theta, alpha, beta) of every measured
//                 (light, view), so btf_eval_measured uses exactly the model's stencils.
//                 Layout measured (mlvq.h): integers, the node of the pair itself.
//   dir_index / dir_weight  (layout measured only) the parabolic Delaunay maps of
//                 codecs/gpu_export.h: btf_eval(wl, wv) blends btf_eval_measured over the 3 x 3
//                 pairs they give, as the model's eval_dir blends over core/interp.h's weights.
//                 The manifest's evaluation.layout says which ("grid" when absent).
// 1D arrays: entry i at texel (i % width, i / width), width = min(count, k_line_width); rows past
// the end are zero. Float textures: decoded = stored * scale (a power of two, manifest + shader).
#pragma once
#include <string>

#include "codecs/gpu_export.h"

namespace btfc::gpu::mlvq_export {

// GLES 3.0 guarantees MAX_TEXTURE_SIZE >= 2048: rows this wide load on every conforming device.
constexpr uint32_t k_line_width = 2048;

// Texture name of a codebook array: "rgb4_index", "lum2_scale", ...
std::string book_texture(const char* part, int level, const char* what);

std::string shader(const ExportBundle& b);
void emulate(const ExportBundle& b, const ShaderQuery& q, float* rgb);

}  // namespace btfc::gpu::mlvq_export
