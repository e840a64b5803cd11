// Synthetic BTF generator (contract in core/synth.h).
//
// Determinism: every random parameter is drawn up front from one std::mt19937_64 in a fixed order
// (raw 64-bit outputs turned into doubles by hand: the std distributions differ between standard
// libraries); per-texel noise is a hash of (seed, x, y), not a draw, so texels can be computed in
// any order. Each texel is then a pure function of those parameters, so the OpenMP split does not
// change a single bit.
//
// Geometry: texel (x, y) sits at (x, y) in the tangent frame, one texel = one length unit, heights
// in the same unit. The height field is periodic over the texel grid (integer frequencies, wrapped
// bump distances), so the material tiles and the shadow rays can wrap around.
#include "core/synth.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

namespace btfc {
namespace {

constexpr double k_pi = 3.14159265358979323846;

struct Rng {
  std::mt19937_64 gen;
  explicit Rng(uint64_t seed) : gen(seed) {}
  double uniform() { return double(gen() >> 11) * 0x1.0p-53; }  // [0, 1), 53 bits
  double uniform(double lo, double hi) { return lo + (hi - lo) * uniform(); }
};

// splitmix64 finaliser: a well-mixed hash for per-texel noise in [0, 1).
double hash01(uint64_t seed, uint64_t x, uint64_t y, uint64_t k) {
  uint64_t z = seed ^ (x * 0x9E3779B97F4A7C15ull) ^ (y * 0xC2B2AE3D27D4EB4Full) ^ (k * 0x165667B19E3779F9ull);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  z ^= z >> 31;
  return double(z >> 11) * 0x1.0p-53;
}

// Shortest signed distance on a ring of length n (periodic texel grid).
double wrap_delta(double d, int n) { return d - n * std::round(d / n); }

struct Material {
  int w = 0, h = 0;
  std::vector<float> height;     // w*h, range [-bump, bump]
  float hmax = 0;
  std::vector<Vec3> normal;      // w*h unit normals
  std::vector<float> kd;         // w*h*3 albedo
  std::vector<float> ks, alpha;  // w*h
};

void build_height(const SynthOptions& o, Rng& rng, Material& m) {
  const int w = o.width, h = o.height;
  std::vector<double> hf(size_t(w) * h, 0.0);
  // ~6 sinusoids with wavelengths of 5..24 texels; frequencies rounded to whole periods per tile.
  for (int k = 0; k < 6; ++k) {
    const double lambda = rng.uniform(5, 24), ang = rng.uniform(0, 2 * k_pi), phase = rng.uniform(0, 2 * k_pi);
    const double amp = rng.uniform(0.4, 1.0);
    double fx = std::round(w * std::cos(ang) / lambda), fy = std::round(h * std::sin(ang) / lambda);
    if (fx == 0 && fy == 0) fx = 1;  // small tiles: the longest periodic wave
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        hf[size_t(x) + size_t(w) * y] += amp * std::sin(2 * k_pi * (fx * x / w + fy * y / h) + phase);
  }
  // A few gaussian bumps (pebbles): local relief the sinusoids lack.
  for (int k = 0; k < 4; ++k) {
    const double cx = rng.uniform(0, w), cy = rng.uniform(0, h), sigma = rng.uniform(1.5, 5), amp = rng.uniform(0.8, 1.6);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        const double dx = wrap_delta(x - cx, w), dy = wrap_delta(y - cy, h);
        hf[size_t(x) + size_t(w) * y] += amp * std::exp(-(dx * dx + dy * dy) / (2 * sigma * sigma));
      }
  }
  // Each component has amplitude ~bump texels (sinusoids 0.4..1, bumps 0.8..1.6 times bump), so
  // relief and slopes scale with bump; the mean height is removed. A 1x1 tile is flat.
  double mean = 0;
  for (double v : hf) mean += v;
  mean /= double(hf.size());
  m.height.resize(hf.size());
  for (size_t i = 0; i < hf.size(); ++i) m.height[i] = hf.size() > 1 ? float((hf[i] - mean) * o.bump) : 0.0f;
  m.hmax = *std::max_element(m.height.begin(), m.height.end());

  // Normals from periodic central differences.
  m.normal.resize(hf.size());
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      auto at = [&](int xx, int yy) { return m.height[size_t((xx + w) % w) + size_t(w) * size_t((yy + h) % h)]; };
      const float gx = 0.5f * (at(x + 1, y) - at(x - 1, y)), gy = 0.5f * (at(x, y + 1) - at(x, y - 1));
      const float inv = 1.0f / std::sqrt(gx * gx + gy * gy + 1.0f);
      m.normal[size_t(x) + size_t(w) * y] = {-gx * inv, -gy * inv, inv};
    }
}

// Two-tone material: periodic Voronoi cells, each cell one of two tones (albedo, shininess), with
// per-cell brightness jitter and per-texel noise. Cell borders give sharp spatial edges.
void build_material(const SynthOptions& o, Rng& rng, Material& m) {
  const int w = o.width, h = o.height;
  double tone_kd[2][3], tone_ks[2], tone_alpha[2];
  for (int t = 0; t < 2; ++t) {
    for (double& c : tone_kd[t]) c = rng.uniform(0.15, 0.8);
    tone_ks[t] = rng.uniform(0.1, 0.6);
    tone_alpha[t] = rng.uniform(8, 64);
  }
  const int cells = std::clamp(w * h / 150, 2, 48);
  std::vector<double> cx(cells), cy(cells), jitter(cells);
  std::vector<int> tone(cells);
  for (int c = 0; c < cells; ++c) {
    cx[c] = rng.uniform(0, w), cy[c] = rng.uniform(0, h), jitter[c] = rng.uniform(0.8, 1.15);
    tone[c] = rng.uniform() < 0.5 ? 0 : 1;
  }
  tone[0] = 0, tone[1] = 1;  // both tones present
  const size_t n = size_t(w) * h;
  m.kd.resize(n * 3), m.ks.resize(n), m.alpha.resize(n);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      int best = 0;
      double best_d = 1e300;
      for (int c = 0; c < cells; ++c) {
        const double dx = wrap_delta(x - cx[c], w), dy = wrap_delta(y - cy[c], h), d = dx * dx + dy * dy;
        if (d < best_d) best_d = d, best = c;
      }
      const size_t i = size_t(x) + size_t(w) * y;
      const int t = tone[best];
      const double grain = 0.85 + 0.3 * hash01(o.seed, x, y, 0);
      for (int c = 0; c < 3; ++c) m.kd[i * 3 + c] = float(std::min(0.95, tone_kd[t][c] * jitter[best] * grain));
      m.ks[i] = float(std::clamp(tone_ks[t] * (0.8 + 0.4 * hash01(o.seed, x, y, 1)), 0.1, 0.6));
      m.alpha[i] = float(std::clamp(tone_alpha[t] * (0.8 + 0.4 * hash01(o.seed, x, y, 2)), 8.0, 64.0));
    }
}

// Per direction: horizontal unit step and ray rise per texel of horizontal travel.
struct RayDir {
  float ux = 0, uy = 0, rise = 0;
  bool vertical = true;  // theta ~ 0: nothing can occlude
};

std::vector<RayDir> ray_dirs(const DirectionSet& s) {
  std::vector<RayDir> out;
  for (const Vec3& d : s.dirs) {
    RayDir r;
    const float hl = std::sqrt(d.x * d.x + d.y * d.y);
    if (hl > 1e-6f && d.z > 0) r = {d.x / hl, d.y / hl, d.z / hl, false};
    out.push_back(r);
  }
  return out;
}

// Soft visibility of direction r from texel (x, y): march 0.5-texel steps up to 32 texels over the
// periodic height field; the deepest the ray runs under the surface sets the attenuation, down to
// 0.15 (not 0: measured BTFs keep interreflected light in shadows).
float visibility(const Material& m, int x, int y, const RayDir& r) {
  if (r.vertical) return 1.0f;
  const int w = m.w, h = m.h;
  const float h0 = m.height[size_t(x) + size_t(w) * y];
  float occ = 0;
  for (int k = 1; k <= 64; ++k) {
    const float t = 0.5f * k, ray = h0 + t * r.rise;
    if (ray > m.hmax) break;
    const float px = x + t * r.ux, py = y + t * r.uy;
    const float fx = std::floor(px), fy = std::floor(py), ax = px - fx, ay = py - fy;
    const int x0 = ((int(fx) % w) + w) % w, y0 = ((int(fy) % h) + h) % h, x1 = (x0 + 1) % w, y1 = (y0 + 1) % h;
    const float* H = m.height.data();
    const float s = (1 - ay) * ((1 - ax) * H[x0 + size_t(w) * y0] + ax * H[x1 + size_t(w) * y0]) +
                    ay * ((1 - ax) * H[x0 + size_t(w) * y1] + ax * H[x1 + size_t(w) * y1]);
    occ = std::max(occ, s - ray);
  }
  const float depth = std::clamp((occ - 1e-4f) / 0.25f, 0.0f, 1.0f);  // 0.25-texel penumbra
  return 1.0f - 0.85f * depth;
}

}  // namespace

Result<Btf> synthesize_btf(const SynthOptions& opt) {
  if (!std::isfinite(opt.bump) || opt.bump < 0)
    return invalid_argument("synth: bump must be finite and >= 0, got " + std::to_string(opt.bump));
  if (!std::isfinite(opt.scale) || opt.scale < 0)
    return invalid_argument("synth: scale must be finite and >= 0, got " + std::to_string(opt.scale));
  if (!std::isfinite(opt.noise) || opt.noise < 0 || opt.noise > 10)
    return invalid_argument("synth: noise must be within [0, 10], got " + std::to_string(opt.noise));
  BtfDesc desc;
  desc.width = opt.width, desc.height = opt.height, desc.channels = 3;
  desc.lights = opt.lights, desc.views = opt.views;
  // Any rescaled output is linear float data, not [0, 1] display data: PSNR and SSIM must use
  // the data peak (at scale 1e-6 a peak of 1 would report 149 dB and SSIM 1.0).
  desc.hdr = opt.scale != 1.0f;
  BTFC_ASSIGN_OR_RETURN(Btf btf, Btf::create(desc));  // validates sizes and directions

  Rng rng(opt.seed);
  Material m;
  m.w = opt.width, m.h = opt.height;
  build_height(opt, rng, m);
  build_material(opt, rng, m);

  const size_t nl = desc.num_lights(), nv = desc.num_views();
  const std::vector<RayDir> lray = ray_dirs(desc.lights), vray = ray_dirs(desc.views);
  std::vector<Vec3> half(nl * nv);  // half vectors, shared by all texels
  for (size_t v = 0; v < nv; ++v)
    for (size_t l = 0; l < nl; ++l) {
      const Vec3 &L = desc.lights.dirs[l], &V = desc.views.dirs[v];
      const float x = L.x + V.x, y = L.y + V.y, z = L.z + V.z, len = std::sqrt(x * x + y * y + z * z);
      half[l + nl * v] = len > 1e-12f ? Vec3{x / len, y / len, z / len} : Vec3{0, 0, 1};
    }

  const long texels = long(desc.num_texels());
#pragma omp parallel
  {
    std::vector<float> sl(nl), sv(nv);
#pragma omp for schedule(dynamic, 16)
    for (long t = 0; t < texels; ++t) {
      const int x = int(t % opt.width), y = int(t / opt.width);
      for (size_t l = 0; l < nl; ++l) sl[l] = visibility(m, x, y, lray[l]);
      for (size_t v = 0; v < nv; ++v) sv[v] = visibility(m, x, y, vray[v]);
      const Vec3 n = m.normal[size_t(t)];
      const float* kd = &m.kd[size_t(t) * 3];
      const float ks = m.ks[size_t(t)], alpha = m.alpha[size_t(t)];
      const float spec_norm = ks * (alpha + 8) / float(8 * k_pi), inv_pi = float(1 / k_pi);
      float* out = btf.abrdf(size_t(t));
      for (size_t v = 0; v < nv; ++v) {
        const bool view_up = desc.views.dirs[v].z > 0;
        for (size_t l = 0; l < nl; ++l, out += 3) {
          const float cos_l = desc.lights.dirs[l].z;
          if (!view_up || cos_l <= 0) {  // below the horizon: no light reaches / no texel visible
            out[0] = out[1] = out[2] = 0;
            continue;
          }
          const Vec3& hv = half[l + nl * v];
          const float ndh = std::max(n.x * hv.x + n.y * hv.y + n.z * hv.z, 0.0f);
          const float spec = ndh > 0 ? spec_norm * std::pow(ndh, alpha) : 0.0f;
          const float k = cos_l * sl[l] * sv[v];
          for (int c = 0; c < 3; ++c) out[c] = k * (kd[c] * inv_pi + spec) * opt.scale;
          if (opt.noise > 0)  // Box-Muller from two hashes of (texel, image, channel): order-free
            for (int c = 0; c < 3; ++c) {
              const uint64_t key = (uint64_t(l + nl * v) * 3 + uint64_t(c)) * 2;
              const uint64_t ns = opt.seed ^ 0x6E6F697365ull;  // not the albedo's hashes
              const double u1 = hash01(ns, uint64_t(t), key, 3), u2 = hash01(ns, uint64_t(t), key + 1, 3);
              const double g = std::sqrt(-2 * std::log(1 - u1)) * std::cos(2 * k_pi * u2);
              out[c] *= float(std::max(0.0, 1 + double(opt.noise) * g));
            }
        }
      }
    }
  }
  return btf;
}

}  // namespace btfc
