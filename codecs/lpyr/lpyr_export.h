// lpyr GPU export (codecs/lpyr/lpyr_export.cpp): the section 3.3 maps of seed 001 as KTX2
// textures and a GLSL ES 3.00 shader with continuous level of detail (eq. 7).
//
// Shader functions besides the contract's btf_eval / btf_eval_measured (which use lod 0, so they
// equal the model's eval / eval_dir):
//   vec3 btf_eval_measured_lod(vec2 uv, int light, int view, float lod)
//   vec3 btf_eval_lod(vec2 uv, vec3 wl, vec3 wv, float lod)        Delaunay, 9 lookups
//   vec3 btf_eval_nearest_lod(vec2 uv, vec3 wl, vec3 wv, float lod) the paper's section 3.4
//        renderer: nearest measured directions from the 32 x 32 parabolic lookup table, and the
//        top-level Y mean evaluated by the Phong model at the actual (wl, wv) (eq. 5)
//   float btf_lod(float footprint)  the paper's range-based selection lambda =
//        min(lmax, max(log2(footprint), 0)), footprint = texels per pixel (the paper uses the
//        viewer distance d as that footprint)
// lod is clamped to [0, lmax]; lod = k (integer) is the BTF filtered to pyramid level k.
#pragma once
#include "codecs/gpu_export.h"

namespace btfc::gpu {

enum class LpyrRenderer { delaunay, nearest };

// CPU emulation of btf_eval_measured_lod (q.light >= 0), btf_eval_lod (delaunay) and
// btf_eval_nearest_lod (nearest) from the bundle's stored texture values only.
void lpyr_emulate(const ExportBundle& b, const ShaderQuery& q, float lod, LpyrRenderer r, float* rgb);

}  // namespace btfc::gpu
