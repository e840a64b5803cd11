// mlvq 4D parameterisation, resampling and colour model; contracts in mlvq_internal.h.
#include <algorithm>
#include <cmath>

#include "codecs/mlvq/mlvq_internal.h"

namespace btfc::mlvq {

namespace {
constexpr double k_pi = 3.14159265358979323846;

// Clamped (non-periodic) axis: node units in [0, n - 1].
float clamp_axis(double c, int n) { return float(std::clamp(c, 0.0, double(std::max(n - 1, 0)))); }
}  // namespace

GridCoord grid_coord(const Grid& g, const Vec3& wl, const Vec3& wv) {
  double tv, pv;
  dir_to_theta_phi(wv, tv, pv);
  if (pv < 0) pv += 2 * k_pi;
  GridCoord c;
  c.theta = g.ntheta > 1 ? clamp_axis(tv / (0.5 * k_pi) * (g.ntheta - 1), g.ntheta) : 0.f;
  c.phi = float(pv / (2 * k_pi) * g.nphi);
  if (!(c.phi < float(g.nphi))) c.phi = 0;  // 2 pi rounds up to nphi
  // The light in the frame rotated by -phi_v (so the view lies in the x-z plane).
  const double cp = std::cos(pv), sp = std::sin(pv);
  const double lx = cp * wl.x + sp * wl.y, ly = -sp * wl.x + cp * wl.y, lz = std::max(0.0, double(wl.z));
  const double len = std::sqrt(lx * lx + ly * ly + lz * lz);
  const double a = std::atan2(lx, lz), sb = len > 0 ? std::clamp(ly / len, -1.0, 1.0) : 0.0;
  c.alpha = g.nalpha > 1 ? clamp_axis((a + 0.5 * k_pi) / k_pi * (g.nalpha - 1), g.nalpha) : 0.f;
  c.beta = g.nbeta > 1 ? clamp_axis((sb + 1) * 0.5 * (g.nbeta - 1), g.nbeta) : 0.f;
  return c;
}

void node_dirs(const Grid& g, int iphi, int itheta, int ialpha, int ibeta, Vec3& wl, Vec3& wv) {
  const double tv = g.ntheta > 1 ? 0.5 * k_pi * itheta / (g.ntheta - 1) : 0.0;
  const double pv = 2 * k_pi * iphi / g.nphi;
  wv = dir_from_theta_phi(tv, pv);
  const double a = g.nalpha > 1 ? -0.5 * k_pi + k_pi * ialpha / (g.nalpha - 1) : 0.0;
  const double sb = g.nbeta > 1 ? -1.0 + 2.0 * ibeta / (g.nbeta - 1) : 0.0;
  const double cb = std::sqrt(std::max(0.0, 1 - sb * sb));
  const double lx = cb * std::sin(a), ly = sb, lz = cb * std::cos(a);
  const double cp = std::cos(pv), sp = std::sin(pv);
  wl = Vec3{float(cp * lx - sp * ly), float(sp * lx + cp * ly), float(lz)};
}

Grid measured_grid(const BtfDesc& d) {
  Grid g;
  g.layout = k_layout_measured;
  g.nl = int(d.num_lights()), g.nv = int(d.num_views());
  auto split = [](int n, int& outer, int& inner) {
    inner = std::max(1, int(std::ceil(std::sqrt(double(n)) - 1e-9)));
    outer = (n + inner - 1) / inner;
  };
  split(g.nl, g.nalpha, g.nbeta);
  split(g.nv, g.nphi, g.ntheta);
  return g;
}

void node_measured(const Grid& g, size_t node, uint32_t& light, uint32_t& view) {
  const size_t ib = node % size_t(g.nbeta), ia = node / size_t(g.nbeta) % size_t(g.nalpha);
  const size_t r = node / (size_t(g.nbeta) * size_t(g.nalpha));
  const size_t it = r % size_t(g.ntheta), ip = r / size_t(g.ntheta);
  light = uint32_t(std::min(ia * size_t(g.nbeta) + ib, size_t(g.nl - 1)));
  view = uint32_t(std::min(ip * size_t(g.ntheta) + it, size_t(g.nv - 1)));
}

Stencil measured_stencil(const Grid& g, const BtfDesc& d, size_t light, size_t view) {
  if (!g.measured()) return stencil(g, grid_coord(g, d.lights.dirs[light], d.views.dirs[view]));
  Stencil s;
  const int c[4] = {int(light % size_t(g.nbeta)), int(light / size_t(g.nbeta)), int(view % size_t(g.ntheta)), int(view / size_t(g.ntheta))};
  for (int a = 0; a < 4; ++a) s.i[a][0] = s.i[a][1] = c[a], s.w[a][0] = 1, s.w[a][1] = 0;
  return s;
}

Stencil stencil(const Grid& g, const GridCoord& c) {
  Stencil s;
  const float v[4] = {c.beta, c.alpha, c.theta, c.phi};
  for (int a = 0; a < 4; ++a) {
    const int n = g.n(a + 1);
    if (n == 1) {
      s.i[a][0] = s.i[a][1] = 0, s.w[a][0] = 1, s.w[a][1] = 0;
      continue;
    }
    const float f = std::floor(v[a]);
    int i0 = int(f);
    float t = v[a] - f;
    if (a == 3) {  // phi is periodic
      i0 = ((i0 % n) + n) % n;
      s.i[a][0] = i0, s.i[a][1] = (i0 + 1) % n;
    } else {
      if (i0 >= n - 1) i0 = n - 2, t = 1;
      if (i0 < 0) i0 = 0, t = 0;
      s.i[a][0] = i0, s.i[a][1] = i0 + 1;
    }
    s.w[a][0] = 1 - t, s.w[a][1] = t;
  }
  return s;
}

void rgb_to_lrg(const float* rgb, float* lrg) {
  const float r = std::max(rgb[0], 0.f), g = std::max(rgb[1], 0.f), b = std::max(rgb[2], 0.f);
  const float s = r + g + b;
  lrg[0] = s * (1.f / 3.f);
  if (s > 0) lrg[1] = r / s, lrg[2] = g / s;
  else lrg[1] = lrg[2] = 1.f / 3.f;
}

void lrg_to_rgb(const float* lrg, float* rgb) {
  const float s = 3 * lrg[0];
  rgb[0] = s * lrg[1];
  rgb[1] = s * lrg[2];
  rgb[2] = s * (1 - lrg[1] - lrg[2]);
}

ResamplePlan make_plan(const BtfDesc& d, const Grid& g) {
  ResamplePlan p;
  p.grid = g;
  p.channels = d.channels;
  const DirectionInterpolator li(d.lights), vi(d.views);
  const size_t n = g.size();
  p.off.resize(n);
  p.w.resize(n);
  const size_t nl = d.num_lights();
  if (g.measured()) {  // no resampling: each node is one measured value
    p.direct = true;
    for (size_t node = 0; node < n; ++node) {
      uint32_t l, v;
      node_measured(g, node, l, v);
      p.off[node].fill(0), p.w[node].fill(0.f);
      p.off[node][0] = uint32_t(size_t(d.channels) * (size_t(l) + nl * size_t(v)));
      p.w[node][0] = 1;
    }
    return p;
  }
#pragma omp parallel for schedule(static)
  for (size_t node = 0; node < n; ++node) {
    size_t r = node;
    const int ib = int(r % size_t(g.nbeta)); r /= size_t(g.nbeta);
    const int ia = int(r % size_t(g.nalpha)); r /= size_t(g.nalpha);
    const int it = int(r % size_t(g.ntheta)); r /= size_t(g.ntheta);
    const int ip = int(r);
    Vec3 wl, wv;
    node_dirs(g, ip, it, ia, ib, wl, wv);
    const DirWeights a = li.weights(wl), b = vi.weights(wv);
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) {
        p.off[node][size_t(3 * i + j)] = uint32_t(size_t(d.channels) * (size_t(a.index[size_t(i)]) + nl * size_t(b.index[size_t(j)])));
        p.w[node][size_t(3 * i + j)] = a.weight[size_t(i)] * b.weight[size_t(j)];
      }
  }
  return p;
}

void extract(const ResamplePlan& p, const float* abrdf, size_t first, size_t count, float* lum, float* chroma) {
  for (size_t k = 0; k < count; ++k) {
    const auto& off = p.off[first + k];
    const auto& w = p.w[first + k];
    float rgb[3] = {0, 0, 0};
    if (p.direct) {
      const float* v = abrdf + off[0];
      rgb[0] = v[0], rgb[1] = p.channels == 3 ? v[1] : v[0], rgb[2] = p.channels == 3 ? v[2] : v[0];
    } else if (p.channels == 3) {
      for (int j = 0; j < 9; ++j) {
        const float* v = abrdf + off[size_t(j)];
        rgb[0] += w[size_t(j)] * v[0], rgb[1] += w[size_t(j)] * v[1], rgb[2] += w[size_t(j)] * v[2];
      }
    } else {  // grey BTFs: one channel replicated (chromaticity 1/3)
      for (int j = 0; j < 9; ++j) rgb[0] += w[size_t(j)] * abrdf[off[size_t(j)]];
      rgb[1] = rgb[2] = rgb[0];
    }
    float lrg[3];
    rgb_to_lrg(rgb, lrg);
    if (lum) lum[k] = lrg[0];
    if (chroma) chroma[2 * k] = lrg[1], chroma[2 * k + 1] = lrg[2];
  }
}

}  // namespace btfc::mlvq
