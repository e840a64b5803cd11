#include "codecs/render.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <memory>

#include "core/sh.h"  // hemisphere_cell_weights: the same quadrature lpca's SH projection uses
#include "core/interp.h"
#include "core/metrics.h"
#include "codecs/preview_panel.h"  // heat_color: one ramp for side_by_side and the panels

namespace btfc {
namespace {

constexpr double k_pi = 3.14159265358979323846;
constexpr size_t k_chunk = size_t(1) << 16;  // queries per evaluator call: bounds the memory

struct V3 {
  double x = 0, y = 0, z = 0;
};
V3 v3(const Vec3& v) { return {v.x, v.y, v.z}; }
Vec3 f3(const V3& v) { return {float(v.x), float(v.y), float(v.z)}; }
V3 operator+(V3 a, V3 b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
V3 operator-(V3 a, V3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
V3 operator*(double s, V3 a) { return {s * a.x, s * a.y, s * a.z}; }
double dot(V3 a, V3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
V3 cross(V3 a, V3 b) { return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x}; }
V3 normalize(V3 a) {
  const double n = std::sqrt(dot(a, a));
  return n > 0 ? (1.0 / n) * a : V3{0, 0, 1};
}

// Bilinear lookup of a lat-long environment (layout in render.h), RGB.
void env_lookup(const RgbImage& env, V3 d, double out[3]) {
  d = normalize(d);
  const double th = std::acos(std::clamp(d.z, -1.0, 1.0));
  double ph = std::atan2(d.y, d.x);
  if (ph < 0) ph += 2 * k_pi;
  const double fx = ph / (2 * k_pi) * env.width - 0.5, fy = th / k_pi * env.height - 0.5;
  const int x0 = int(std::floor(fx)), y0 = int(std::floor(fy));
  const double ax = fx - x0, ay = fy - y0;
  out[0] = out[1] = out[2] = 0;
  for (int j = 0; j < 2; ++j)
    for (int i = 0; i < 2; ++i) {
      const int xx = ((x0 + i) % env.width + env.width) % env.width;  // phi wraps
      const int yy = std::clamp(y0 + j, 0, env.height - 1);           // theta clamps at the poles
      const double w = (i ? ax : 1 - ax) * (j ? ay : 1 - ay);
      const float* p = env.rgb.data() + (size_t(yy) * size_t(env.width) + size_t(xx)) * 3;
      for (int c = 0; c < 3; ++c) out[c] += w * p[c];
    }
}

// Queries with the weight (RGB) each result is accumulated into its pixel with; flushed through
// the evaluator in chunks.
class Accumulator {
 public:
  Accumulator(const BtfEvaluator& eval, RgbImage& img) : m_eval(eval), m_img(img) {}
  Status add(size_t pixel, int x, int y, V3 wl, V3 wv, const double w[3]) {
    m_q.push_back(EvalQuery{x, y, -1, -1, f3(wl), f3(wv)});
    m_pix.push_back(pixel);
    m_w.insert(m_w.end(), {float(w[0]), float(w[1]), float(w[2])});
    return m_q.size() >= k_chunk ? flush() : Status{};
  }
  Status flush() {
    if (m_q.empty()) return {};
    m_out.resize(m_q.size() * 3);
    BTFC_RETURN_IF_ERROR(m_eval(m_q, m_out.data()));
    for (size_t i = 0; i < m_q.size(); ++i)
      for (int c = 0; c < 3; ++c) m_img.rgb[m_pix[i] * 3 + size_t(c)] += m_w[i * 3 + size_t(c)] * m_out[i * 3 + size_t(c)];
    m_q.clear(), m_pix.clear(), m_w.clear();
    return {};
  }

 private:
  const BtfEvaluator& m_eval;
  RgbImage& m_img;
  std::vector<EvalQuery> m_q;
  std::vector<size_t> m_pix;
  std::vector<float> m_w, m_out;
};

// Lights one surface point: local frame (t, b, n) in world, texel (x, y), world position p.
struct Shading {
  const RenderSettings& s;
  const DirectionSet& lights;
  const std::vector<double>& cell_w;  // environment quadrature
  // `scale` weights this texel's share of the pixel (bilinear texture filtering).
  Status shade(Accumulator& acc, size_t pixel, int x, int y, V3 p, V3 t, V3 b, V3 n, double scale = 1) const {
    auto local = [&](V3 d) { return V3{dot(d, t), dot(d, b), dot(d, n)}; };
    const V3 wv = local(normalize(v3(s.view)));
    if (wv.z <= 0) return {};
    if (s.light_kind == RenderSettings::LightKind::environment) {
      for (size_t l = 0; l < lights.size(); ++l) {
        const V3 wl = v3(lights.dirs[l]);
        double L[3];
        env_lookup(s.environment, wl.x * t + wl.y * b + wl.z * n, L);
        if (L[0] == 0 && L[1] == 0 && L[2] == 0) continue;
        for (double& c : L) c *= cell_w[l] * s.intensity * scale;
        BTFC_RETURN_IF_ERROR(acc.add(pixel, x, y, wl, wv, L));
      }
      return {};
    }
    V3 dir = normalize(v3(s.light));
    double e = s.intensity * scale;
    if (s.light_kind == RenderSettings::LightKind::point) {
      const V3 d = s.distance * dir - p;
      const double r = std::sqrt(dot(d, d));
      if (r <= 0) return {};
      dir = (1.0 / r) * d;
      e *= (s.distance / r) * (s.distance / r);
    }
    const V3 wl = local(dir);
    if (wl.z <= 0) return {};
    const double w[3] = {e, e, e};
    return acc.add(pixel, x, y, wl, wv, w);
  }
};

}  // namespace

BtfEvaluator model_evaluator(const Model& model) {
  return [&model](std::span<const EvalQuery> q, float* rgb) -> Status {
    const int nc = model.desc().channels;
    if (nc == 3) return model.eval_batch(q, rgb);
    std::vector<float> tmp(q.size() * size_t(nc));
    BTFC_RETURN_IF_ERROR(model.eval_batch(q, tmp.data()));
    for (size_t i = 0; i < q.size(); ++i)
      for (int c = 0; c < 3; ++c) rgb[i * 3 + size_t(c)] = tmp[i * size_t(nc) + size_t(std::min(c, nc - 1))];
    return {};
  };
}

BtfEvaluator btf_evaluator(const Btf& btf) {
  auto li = std::make_shared<DirectionInterpolator>(btf.desc().lights);
  auto vi = std::make_shared<DirectionInterpolator>(btf.desc().views);
  return [&btf, li, vi](std::span<const EvalQuery> q, float* rgb) -> Status {
    const BtfDesc& d = btf.desc();
    for (const EvalQuery& e : q)
      if (e.x < 0 || e.y < 0 || e.x >= d.width || e.y >= d.height)
        return invalid_argument("render: texel (" + std::to_string(e.x) + ", " + std::to_string(e.y) + ") is outside the BTF");
    const int nc = d.channels;
#pragma omp parallel for schedule(static)
    for (size_t i = 0; i < q.size(); ++i) {
      const DirWeights wl = li->weights(q[i].wl), wv = vi->weights(q[i].wv);
      const float* a = btf.abrdf(size_t(q[i].x) + size_t(d.width) * size_t(q[i].y));
      float acc[3] = {0, 0, 0};
      for (int j = 0; j < 3; ++j)
        for (int k = 0; k < 3; ++k) {
          const float w = wl.weight[size_t(j)] * wv.weight[size_t(k)];
          if (w == 0) continue;
          const size_t row = d.row(size_t(wl.index[size_t(j)]), size_t(wv.index[size_t(k)]), 0);
          for (int c = 0; c < 3; ++c) acc[c] += w * a[row + size_t(std::min(c, nc - 1))];
        }
      for (int c = 0; c < 3; ++c) rgb[i * 3 + size_t(c)] = acc[c];
    }
    return {};
  };
}

Result<RgbImage> render(const BtfDesc& desc, const BtfEvaluator& eval, const RenderSettings& s) {
  const bool env = s.light_kind == RenderSettings::LightKind::environment;
  if (env) {
    const RgbImage& e = s.environment;
    if (e.width <= 0 || e.height <= 0 || e.rgb.size() != size_t(e.width) * size_t(e.height) * 3)
      return invalid_argument("render: the environment map is empty or its size does not match its pixels");
    for (float v : e.rgb)
      if (!std::isfinite(v)) return invalid_argument("render: the environment map holds NaN or Inf");
  }
  if (!std::isfinite(s.intensity) || !std::isfinite(s.distance) || (s.light_kind == RenderSettings::LightKind::point && s.distance <= 0))
    return invalid_argument("render: light intensity and distance must be finite (distance > 0)");
  const std::vector<double> cell_w = env ? sh::hemisphere_cell_weights(desc.lights) : std::vector<double>{};
  const Shading shading{s, desc.lights, cell_w};
  RgbImage img;
  if (s.shape == RenderSettings::Shape::flat) {
    if (s.view.z <= 0) return invalid_argument("render: the view direction is below the flat sample's horizon");
    img.width = desc.width, img.height = desc.height;
    img.rgb.assign(desc.num_texels() * 3, 0.f);
    Accumulator acc(eval, img);
    const double aspect = double(desc.height) / desc.width;
    for (int y = 0; y < desc.height; ++y)
      for (int x = 0; x < desc.width; ++x) {
        const V3 p{(x + 0.5) / desc.width - 0.5, (0.5 - (y + 0.5) / desc.height) * aspect, 0};
        BTFC_RETURN_IF_ERROR(shading.shade(acc, size_t(y) * size_t(desc.width) + size_t(x), x, y, p, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}));
      }
    BTFC_RETURN_IF_ERROR(acc.flush());
    return img;
  }
  if (s.size < 1 || s.size > 8192 || s.tiles < 1 || s.tiles > 1024) return invalid_argument("render: sphere size must be in [1, 8192] and tiles in [1, 1024]");
  img.width = img.height = s.size;
  img.rgb.assign(size_t(s.size) * size_t(s.size) * 3, 0.f);
  Accumulator acc(eval, img);
  const V3 v = normalize(v3(s.view));
  const V3 hint = std::abs(v.z) > 0.99 ? V3{0, 1, 0} : V3{0, 0, 1};
  const V3 right = normalize(cross(hint, v)), up = cross(v, right);
  // The texture's axis is the screen's up: the camera faces the sphere's equator and the
  // texture's poles sit at the top and bottom of the silhouette, so the tangent frame is
  // continuous over everything visible. (With the axis towards the camera every texture column
  // met at the disc's centre: a pinwheel of wedges, issue 21.) Texels are filtered bilinearly.
  for (int j = 0; j < s.size; ++j)
    for (int i = 0; i < s.size; ++i) {
      const double px = (i + 0.5) / s.size * 2 - 1, py = 1 - (j + 0.5) / s.size * 2, r2 = px * px + py * py;
      if (r2 >= 1) continue;
      const V3 n = normalize(px * right + py * up + std::sqrt(1 - r2) * v);
      const double th = std::acos(std::clamp(dot(n, up), -1.0, 1.0)), ph = std::atan2(dot(n, right), dot(n, v));
      const V3 tt = cross(up, n);
      if (dot(tt, tt) < 1e-18) continue;  // exactly at a texture pole (on the silhouette)
      const V3 t = normalize(tt), b = cross(n, t);
      // Texture coordinates in texels (2 tiles around, 1 from pole to pole), wrapped; the
      // texture's centre faces the camera, its edges meet at the silhouette.
      const double fu = (ph / k_pi * s.tiles + 0.5) * desc.width - 0.5, fv = th / k_pi * s.tiles * desc.height - 0.5;
      const double x0 = std::floor(fu), y0 = std::floor(fv), ax = fu - x0, ay = fv - y0;
      for (int dy = 0; dy < 2; ++dy)
        for (int dx = 0; dx < 2; ++dx) {
          const double wgt = (dx ? ax : 1 - ax) * (dy ? ay : 1 - ay);
          if (wgt == 0) continue;
          const int tx = int(((int64_t(x0) + dx) % desc.width + desc.width) % desc.width);
          const int ty = int(((int64_t(y0) + dy) % desc.height + desc.height) % desc.height);
          BTFC_RETURN_IF_ERROR(shading.shade(acc, size_t(j) * size_t(s.size) + size_t(i), tx, ty, n, t, b, n, wgt));
        }
    }
  BTFC_RETURN_IF_ERROR(acc.flush());
  return img;
}

void tone_map(RgbImage& img, double exposure_ev, ToneMap curve) {
  const float k = float(std::exp2(exposure_ev));
  for (size_t i = 0; i + 2 < img.rgb.size(); i += 3) {
    float* p = img.rgb.data() + i;
    for (int c = 0; c < 3; ++c) p[c] *= k;
    if (curve != ToneMap::reinhard) continue;
    const float L = 0.2126f * p[0] + 0.7152f * p[1] + 0.0722f * p[2];
    const float f = L > 0 ? 1.0f / (1.0f + L) : 1.0f;
    for (int c = 0; c < 3; ++c) p[c] *= f;
  }
}

namespace {
std::vector<float> luminance(const RgbImage& im) {
  std::vector<float> y(size_t(im.width) * size_t(im.height));
  for (size_t k = 0; k < y.size(); ++k)
    y[k] = 0.2126f * im.rgb[k * 3] + 0.7152f * im.rgb[k * 3 + 1] + 0.0722f * im.rgb[k * 3 + 2];
  return y;
}
}  // namespace

double render_ssim(const RgbImage& reference, const RgbImage& test) {
  if (reference.width != test.width || reference.height != test.height || reference.rgb.empty()) return 0;
  const std::vector<float> a = luminance(reference), b = luminance(test);
  float peak = 0;
  for (float v : a) peak = std::max(peak, v);
  // An all-black reference: the images agree exactly when the test is black too.
  if (peak <= 0) peak = 1;
  return ssim_gray(a.data(), b.data(), reference.width, reference.height, peak);
}

RgbImage side_by_side(const RgbImage& reference, const RgbImage& test, double magnify) {
  const int w = reference.width, h = reference.height, gap = 4;
  RgbImage out;
  out.width = 3 * w + 2 * gap, out.height = h;
  out.rgb.assign(size_t(out.width) * size_t(h) * 3, 1.f);  // white gaps
  std::vector<float> y = luminance(reference);
  std::sort(y.begin(), y.end());
  const float white = y.empty() ? 1.f : std::max(1e-12f, y[std::min(y.size() - 1, size_t(0.995 * double(y.size())))]);
  for (int j = 0; j < h; ++j)
    for (int i = 0; i < w; ++i) {
      const size_t k = (size_t(j) * size_t(w) + size_t(i)) * 3;
      double err = 0;
      for (int c = 0; c < 3; ++c) {
        out.rgb[(size_t(j) * size_t(out.width) + size_t(i)) * 3 + size_t(c)] = std::clamp(reference.rgb[k + size_t(c)] / white, 0.f, 1.f);
        out.rgb[(size_t(j) * size_t(out.width) + size_t(w + gap + i)) * 3 + size_t(c)] = std::clamp(test.rgb[k + size_t(c)] / white, 0.f, 1.f);
        err = std::max(err, double(std::abs(test.rgb[k + size_t(c)] - reference.rgb[k + size_t(c)])));
      }
      // Heat map: black -> red -> yellow -> white as the magnified error grows to 1.
      heat_color(err / white * magnify, out.rgb.data() + (size_t(j) * size_t(out.width) + size_t(2 * (w + gap) + i)) * 3);
    }
  return out;
}

}  // namespace btfc
