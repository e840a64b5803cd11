// lpca GPU export (codecs/lpca/lpca_export.cpp): cluster index, weights, eigen-BRDF table, SH
// coefficients and, for a model with an environment attached (attach_environment in lpca.h),
// the PRT maps of seed 002 section 5 with the shader function
//   vec3 btf_relit(vec2 uv, vec3 wv)
// the radiance leaving texel uv towards the sample-frame view direction wv under that fixed
// environment (eq. 3): sum_m beta_m lambda_m(wv), lambda bilinearly interpolated in the 16 x 16
// parabolic view maps (as the paper's hardware filtering does, computed in float here).
#pragma once
#include "codecs/gpu_export.h"

namespace btfc::gpu {

// CPU emulation of btf_relit from the bundle's stored texture values. Precondition: the bundle
// has the "prt" texture (lpca exported with an environment).
void lpca_emulate_relit(const ExportBundle& b, float u, float v, const Vec3& wv, float* rgb);

}  // namespace btfc::gpu
