#include "core/scene.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "core/interp.h"
#include "core/limits.h"

namespace btfc::gpu {
namespace {

double angle_between(const Vec3& a, const Vec3& b) {
  const double d = double(a.x) * b.x + double(a.y) * b.y + double(a.z) * b.z;
  return std::acos(std::clamp(d, -1.0, 1.0));
}

Status check_keys(const nlohmann::json& o, std::initializer_list<const char*> allowed, const std::string& where) {
  if (!o.is_object()) return invalid_argument(where + ": expected an object");
  for (auto it = o.begin(); it != o.end(); ++it)
    if (std::none_of(allowed.begin(), allowed.end(), [&](const char* k) { return it.key() == k; }))
      return invalid_argument(where + ": unknown key '" + it.key() + "'");
  return {};
}

Result<Cone> parse_cone(const nlohmann::json& c, const std::string& where) {
  BTFC_RETURN_IF_ERROR(check_keys(c, {"theta", "phi", "angle"}, where));
  if (!c.contains("angle") || !c["angle"].is_number()) return invalid_argument(where + ": 'angle' (degrees) is required");
  // json::value() throws on a key of another type ("theta": "x"): check the types first.
  for (const char* k : {"theta", "phi"})
    if (c.contains(k) && !c[k].is_number()) return invalid_argument(where + ": '" + k + "' must be a number (degrees)");
  const double th = c.value("theta", 0.0), ph = c.value("phi", 0.0), an = c["angle"].get<double>();
  if (!(th >= 0 && th <= 90) || !(an > 0 && an <= 180) || !std::isfinite(ph))
    return invalid_argument(where + ": theta must be in [0, 90], angle in (0, 180]");
  Cone k;
  k.axis = dir_from_theta_phi(th * M_PI / 180, ph * M_PI / 180);
  k.angle_deg = an;
  return k;
}

}  // namespace

namespace {

Result<SceneMaterial> parse_scene_json(const std::string& text, const std::string& what, const std::string& material) {
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(text);
  } catch (const std::exception& e) {
    return invalid_argument(what + ": not valid JSON: " + e.what());
  }
  BTFC_RETURN_IF_ERROR(check_keys(j, {"materials"}, what));
  if (!j.contains("materials") || !j["materials"].is_array() || j["materials"].empty())
    return invalid_argument(what + ": 'materials' must be a non-empty array");
  for (size_t i = 0; i < j["materials"].size(); ++i) {
    const nlohmann::json& m = j["materials"][i];
    const std::string where = what + ": materials[" + std::to_string(i) + "]";
    BTFC_RETURN_IF_ERROR(check_keys(m, {"name", "footprint", "light_cone", "view_cone", "gpu_budget"}, where));
    SceneMaterial s;
    if (m.contains("name") && !m["name"].is_string()) return invalid_argument(where + ": 'name' must be a string");
    s.name = m.value("name", "");
    if (!material.empty() && s.name != material) continue;
    if (m.contains("footprint")) {
      const nlohmann::json& f = m["footprint"];
      if (!f.is_array() || f.size() != 2 || !f[0].is_number() || !f[1].is_number())
        return invalid_argument(where + ": 'footprint' must be [min, max] texels per pixel");
      s.footprint_min = f[0].get<double>(), s.footprint_max = f[1].get<double>();
      if (!(s.footprint_min > 0 && s.footprint_min <= s.footprint_max && s.footprint_max < 1e9))
        return invalid_argument(where + ": 'footprint' needs 0 < min <= max");
    }
    if (m.contains("light_cone")) {
      BTFC_ASSIGN_OR_RETURN(s.light_cone, parse_cone(m["light_cone"], where + ".light_cone"));
    }
    if (m.contains("view_cone")) {
      BTFC_ASSIGN_OR_RETURN(s.view_cone, parse_cone(m["view_cone"], where + ".view_cone"));
    }
    if (m.contains("gpu_budget")) {
      const nlohmann::json& b = m["gpu_budget"];
      if (b.is_number_unsigned() || (b.is_number_integer() && b.get<int64_t>() > 0)) s.gpu_budget = b.get<uint64_t>();
      else if (b.is_string()) {
        auto n = parse_byte_size(b.get<std::string>());
        if (!n.ok()) return invalid_argument(where + ".gpu_budget: " + n.status().message());
        s.gpu_budget = n.value();
      } else return invalid_argument(where + ": 'gpu_budget' must be bytes or a size like \"64M\"");
    }
    return s;
  }
  return invalid_argument(what + ": no material named '" + material + "'");
}

}  // namespace

Result<SceneMaterial> parse_scene(const std::string& text, const std::string& what, const std::string& material) {
  // The checks above look at every type before reading a value; this catches any they miss (a
  // nlohmann::json type_error escaping would end the process instead of naming the file).
  try {
    return parse_scene_json(text, what, material);
  } catch (const nlohmann::json::exception& e) {
    return invalid_argument(what + ": " + e.what());
  }
}

Result<SceneMaterial> read_scene(const std::string& path, const std::string& material) {
  std::ifstream f(path);
  if (!f) return io_error(path + ": cannot open");
  std::stringstream ss;
  ss << f.rdbuf();
  return parse_scene(ss.str(), path, material);
}

void scene_mip_range(const SceneMaterial& s, int& first, int& last) {
  first = int(std::floor(std::log2(std::max(s.footprint_min, 1.0))));
  last = int(std::ceil(std::log2(std::max(s.footprint_max, 1.0)))) + 1;
}

std::vector<int> directions_in_cone(const DirectionSet& set, const std::optional<Cone>& cone) {
  std::vector<int> out;
  if (!cone) {
    for (size_t i = 0; i < set.size(); ++i) out.push_back(int(i));
    return out;
  }
  // Widen by the longest Delaunay edge: every vertex of a triangle containing a point within the
  // cone lies within the cone + that edge length.
  double widen = 0;
  const DirectionInterpolator interp(set);
  for (const auto& t : interp.triangles())
    for (int e = 0; e < 3; ++e) widen = std::max(widen, angle_between(set.dirs[size_t(t[size_t(e)])], set.dirs[size_t(t[size_t((e + 1) % 3)])]));
  const double limit = cone->angle_deg * M_PI / 180 + widen + 1e-6;
  int nearest = 0;
  for (size_t i = 0; i < set.size(); ++i) {
    const double a = angle_between(set.dirs[i], cone->axis);
    if (a <= limit) out.push_back(int(i));
    if (a < angle_between(set.dirs[size_t(nearest)], cone->axis)) nearest = int(i);
  }
  if (out.empty()) out.push_back(nearest);
  return out;
}

}  // namespace btfc::gpu
