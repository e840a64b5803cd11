// The tile-cache simulator's camera path and feedback image (eq. 1 and 2); see tile_cache.h.
#include <algorithm>
#include <cmath>

#include "formats/bsvtf/tile_cache.h"

namespace btfc {
namespace {

constexpr double k_pi = 3.14159265358979323846;

struct V3 {
  double x, y, z;
};
V3 operator+(V3 a, V3 b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
V3 operator*(double s, V3 a) { return {s * a.x, s * a.y, s * a.z}; }

struct Camera {
  V3 eye, forward, right, up;
  double tan_half = 0, aspect = 1;
  int w = 1, h = 1;
  // Hit of the ray through pixel position (px, py) (pixel centres at +0.5) with z = 0.
  bool hit(double px, double py, double& s, double& t) const {
    const double nx = (2 * px / w - 1) * tan_half * aspect, ny = (1 - 2 * py / h) * tan_half;
    const V3 d = forward + nx * right + ny * up;
    if (d.z >= -1e-12) return false;
    const double lambda = -eye.z / d.z;
    s = eye.x + lambda * d.x, t = eye.y + lambda * d.y;
    return std::isfinite(s) && std::isfinite(t);
  }
};

// The path at parameter u in [0, 1]: far (1.6 x the sample size above it) at u = 0 and 1,
// closest (0.12 x) and most grazing (40 degrees elevation) at u = 1/2, half a turn around, the
// look-at point wandering over the sample.
Camera camera_at(const bsvtf::Geometry& g, const CameraPathOptions& p, double u) {
  const double S = std::max(g.width, g.height), W = g.width, H = g.height;
  const double close = 0.5 - 0.5 * std::cos(2 * k_pi * u);  // 0 far .. 1 close
  const double dist = S * std::exp(std::log(1.6) + (std::log(0.12) - std::log(1.6)) * close);
  const double elev = (90.0 - 50.0 * close) * k_pi / 180, azim = k_pi * u;
  const V3 target{W * (0.5 + 0.2 * std::sin(2 * k_pi * u)), H * (0.5 + 0.2 * std::sin(4 * k_pi * u)), 0};
  const V3 back{std::cos(elev) * std::cos(azim), std::cos(elev) * std::sin(azim), std::sin(elev)};
  Camera c;
  c.eye = target + dist * back;
  c.forward = -1.0 * back;
  c.right = {-std::sin(azim), std::cos(azim), 0};  // horizontal, perpendicular to forward
  // up = right x forward: perpendicular to both, tilted towards +z.
  c.up = {c.right.y * c.forward.z - c.right.z * c.forward.y, c.right.z * c.forward.x - c.right.x * c.forward.z,
          c.right.x * c.forward.y - c.right.y * c.forward.x};
  c.tan_half = std::tan(p.fov_deg * k_pi / 360);
  c.w = p.width, c.h = p.height, c.aspect = double(p.width) / p.height;
  return c;
}

}  // namespace

Result<std::vector<FeedbackPixel>> feedback_image(const bsvtf::Geometry& g, const CameraPathOptions& p, int frame) {
  if (p.frames < 1 || p.width < 1 || p.height < 1 || p.width > 8192 || p.height > 8192)
    return invalid_argument("camera path: frames and screen size must be >= 1 (screen <= 8192)");
  if (!(p.fov_deg > 1 && p.fov_deg < 170)) return invalid_argument("camera path: field of view outside (1, 170) degrees");
  if (frame < 0 || frame >= p.frames)
    return invalid_argument("camera path: frame " + std::to_string(frame) + " outside the path's " + std::to_string(p.frames) + " frames");
  const double u = p.kind == CameraPathOptions::Kind::still ? 0.4 : p.frames == 1 ? 0.0 : double(frame) / (p.frames - 1);
  const Camera cam = camera_at(g, p, u);
  const int L = g.finest();
  std::vector<FeedbackPixel> out(size_t(p.width) * size_t(p.height));
  for (int y = 0; y < p.height; ++y)
    for (int x = 0; x < p.width; ++x) {
      double s, t, sx, tx, sy, ty;
      if (!cam.hit(x + 0.5, y + 0.5, s, t) || s < 0 || t < 0 || s >= g.width || t >= g.height) continue;
      FeedbackPixel& f = out[size_t(y) * size_t(p.width) + size_t(x)];
      f.hit = true, f.s = float(s), f.t = float(t);
      // Footprint: distance in texels to the neighbouring pixels' hits (eq. 1). A neighbour
      // ray above the horizon means an unbounded footprint: the coarsest level.
      if (!cam.hit(x + 1.5, y + 0.5, sx, tx) || !cam.hit(x + 0.5, y + 1.5, sy, ty)) continue;
      const double fp = std::max(std::hypot(sx - s, tx - t), std::hypot(sy - s, ty - t));
      f.level = fp <= 0 ? L : std::clamp(int(std::ceil(L - std::log2(fp) - 1e-9)), 0, L);
    }
  return out;
}

}  // namespace btfc
