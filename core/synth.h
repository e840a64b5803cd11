// Synthetic BTF generator (`btfc synth`): a deterministic procedural material with the features
// that make real BTFs hard to compress.
//
// A height field (sum of seeded random-phase sinusoids and bumps) gives per-texel normals;
// each texel's value is  cos(theta_l) * [kd(x)/pi + ks(x) * D_blinn(n, h; alpha(x))] * S_l * S_v
// with a spatially varying albedo kd (RGB, two-tone pattern + noise), specular weight ks and
// exponent alpha, and S_l / S_v the self-shadowing and masking found by marching a ray over the
// height field towards the light / the viewer. The cosine is the *macro* cos(theta_l), as in
// measured BTFs (the data already contains it). Values are linear, roughly within [0, 1].
// `noise` > 0 adds measurement noise: every value (texel, light, view, channel) independently
// multiplied by max(0, 1 + noise g), g standard normal, as photon / Monte Carlo noise that no two
// images share (the albedo grain, by contrast, repeats in every image: it is texture).
// Same parameters -> bit-identical output.
#pragma once
#include <cstdint>

#include "core/btf.h"

namespace btfc {

struct SynthOptions {
  int width = 32, height = 32;
  DirectionSet lights = DirectionSet::ubo2003();
  DirectionSet views = DirectionSet::ubo2003();
  uint64_t seed = 1;
  float bump = 1.0f;    // height-field amplitude (0 = flat)
  float scale = 1.0f;   // multiplies all values (HDR tests use e.g. 1e6)
  float noise = 0.0f;   // relative standard deviation of per-value multiplicative noise (0 = none)
};

Result<Btf> synthesize_btf(const SynthOptions& opt);

}  // namespace btfc
