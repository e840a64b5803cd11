// Scene budgets: "model only what a scene requires" (spec section 1 / issue 8).
//
// scene.json (unknown keys are errors):
//   { "materials": [ {
//       "name": "leather",                 optional; --material picks one, default the first
//       "footprint": [0.5, 16],            texels per screen pixel, min and max over the scene
//       "light_cone": {"theta": 30, "phi": 0, "angle": 40},   optional, degrees: the lights the
//       "view_cone":  {"theta": 0, "phi": 0, "angle": 60},    scene uses lie within `angle` of the axis
//       "gpu_budget": "8M"                 bytes of textures at most (K/M/G suffixes), optional
//   } ] }
//
// What the export keeps (fmf; other codecs check the budget only, see their exporters):
//   - mip levels: a pixel never covers fewer than footprint[0] texels, so levels finer than
//     m0 = floor(log2(max(footprint[0], 1))) are never sampled and are dropped; levels coarser than
//     m1 = ceil(log2(footprint[1])) + 1 likewise (one extra level for trilinear blending);
//   - directions: only measured directions inside a cone widened by the set's largest
//     neighbour spacing (so every Delaunay triangle a query inside the cone needs is kept);
//   - components: the most eigen-components whose textures fit the budget (4 per RGBA texel).
// The report gives the bytes and the predicted error the cut adds: dropped mip levels and
// directions add none inside the scene's range by construction; dropped components add
// sqrt(sum of dropped sigma^2 / sum of sigma^2) relative L2 (Eckart-Young).
#pragma once
#include <optional>
#include <string>
#include <vector>

#include "core/btf.h"
#include "core/status.h"

namespace btfc::gpu {

struct Cone {
  Vec3 axis;
  double angle_deg = 180;
};

struct SceneMaterial {
  std::string name;
  double footprint_min = 1, footprint_max = 1;
  std::optional<Cone> light_cone, view_cone;
  uint64_t gpu_budget = 0;  // 0 = unlimited
};

// Parses scene.json and picks `material` (empty = the first). Errors name the file and key.
Result<SceneMaterial> read_scene(const std::string& path, const std::string& material = "");
Result<SceneMaterial> parse_scene(const std::string& json_text, const std::string& what, const std::string& material = "");

// Mip levels the scene samples: [first, last] (first >= 0; last clamped by the caller).
void scene_mip_range(const SceneMaterial& s, int& first, int& last);
// Indices of `set` inside `cone` widened by the set's largest nearest-neighbour spacing (all
// directions when there is no cone). Never empty: the direction nearest the axis at least.
std::vector<int> directions_in_cone(const DirectionSet& set, const std::optional<Cone>& cone);

}  // namespace btfc::gpu
