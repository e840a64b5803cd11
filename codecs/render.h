// A small CPU renderer of a BTF: the flat sample or a textured sphere under a point light, a
// directional light or a lat-long environment map, seen from a given direction. It renders the
// original data and any codec's Model the same way, so `btfc bench` can compare rendered images
// (SSIM) and write side-by-side previews; `btfc render` exposes it.
//
// Scenes (all directions are unit vectors; theta from +z, phi from +x towards +y):
//  - flat: the sample lies in the world xy plane (its tangent frame = the world frame, z = normal),
//    spanning x in [-0.5, 0.5] and y in [-0.5 h/w, 0.5 h/w]; one image pixel per texel (row 0 at
//    +y), all seen from the one direction `view` (an orthographic camera; the image is shown in
//    texture space, not foreshortened). A point light at `light * distance` (sample widths) gives
//    each texel its own light direction and an irradiance falloff (distance / r)^2, 1 at the centre.
//  - sphere: a unit sphere seen by an orthographic camera from `view` (world), `size` x `size`
//    pixels, background 0. The texture wraps around it about the screen's up axis (the camera
//    faces the equator; the texture's poles are at the top and bottom of the silhouette):
//    u = phi / pi + 1/2 (2 `tiles` repeats, the texture's centre facing the camera), v = theta / pi (`tiles`
//    repeats, theta from the up axis), texels filtered bilinearly. The local frame at a point
//    is t = d/dphi (continuous over the visible half), b = n x t, n; light and view are brought
//    into it (below the local horizon: no light / black).
//  - environment: a lat-long RGB image in world coordinates (row 0 at the zenith +z, phi from +x;
//    the layout of codecs/lpca/lpca.h), integrated over the measured light directions with their
//    hemisphere-cell solid angles (the data already contains the cosine factor):
//        L(x, v) = sum_l dOmega_l L_env(R w_l) rho(x, w_l, v)
//    with R the local-to-world rotation and L_env bilinear in the lat-long image.
// Values are linear RGB (single-channel BTFs replicated to grey).
#pragma once
#include <functional>
#include <span>
#include <string>
#include <vector>

#include "codecs/codec.h"

namespace btfc {

struct RgbImage {
  int width = 0, height = 0;
  std::vector<float> rgb;  // row-major, 3 floats per pixel
};

// Evaluates a BTF at (texel, light direction, view direction) in the sample frame for every
// query (EvalQuery with light = view = -1); writes 3 floats per query.
using BtfEvaluator = std::function<Status(std::span<const EvalQuery>, float* rgb_out)>;
BtfEvaluator model_evaluator(const Model& model);
// The uncompressed data, interpolated between measured directions like a Model (9 lookups).
BtfEvaluator btf_evaluator(const Btf& btf);

struct RenderSettings {
  enum class Shape { flat, sphere } shape = Shape::flat;
  enum class LightKind { directional, point, environment } light_kind = LightKind::directional;
  Vec3 view{0, 0, 1};           // towards the camera (world)
  Vec3 light{0, 0, 1};          // towards the light (world), directional and point
  double distance = 2.0;        // point light: sample widths (flat) or sphere radii from the centre
  double intensity = 1.0;       // scales the light (irradiance at the centre / environment)
  RgbImage environment;         // lat-long, for LightKind::environment
  int size = 128;               // sphere image size in pixels
  int tiles = 1;                // sphere: texture repeats in theta (2 x in phi)
};

// Errors: view below the flat sample's horizon, empty or non-finite environment, bad sizes,
// or whatever the evaluator reports.
Result<RgbImage> render(const BtfDesc& desc, const BtfEvaluator& eval, const RenderSettings& s);

// For display: exposure (values x 2^exposure_ev), then an optional tone curve. `reinhard` maps
// each pixel's luminance L to L / (1 + L), keeping its colour, so the highlights of HDR data stay
// visible in an 8-bit PNG; `none` leaves the values (a PNG then clips at 1).
enum class ToneMap { none, reinhard };
void tone_map(RgbImage& img, double exposure_ev, ToneMap curve);

// SSIM of two renders on luminance, dynamic range = the reference's peak luminance (metrics.h).
double render_ssim(const RgbImage& reference, const RgbImage& test);

// [reference | test | |test - reference| x magnify as a heat map], tone-mapped to [0, 1] by the
// reference's 99.5th-percentile luminance (so PNG previews of HDR data are visible), 4-pixel gap.
RgbImage side_by_side(const RgbImage& reference, const RgbImage& test, double magnify);

}  // namespace btfc
