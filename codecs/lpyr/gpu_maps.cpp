// lpyr: the textures of the paper's renderer (section 3.3) and its nearest-direction lookup
// (section 3.4 step 1). Exact packing documented in lpyr.h.
#include <algorithm>
#include <cmath>

#include "codecs/lpyr/lpyr_internal.h"

namespace btfc::lpyr {
namespace {

constexpr int k_lut_size = 32;

// Slot j (0: Y 1-4, 1: Y 5-8, 2: Cb 1-2 Cr 1-2) of component lane q (RGBA) -> (channel, component).
void slot_source(int j, int q, int& channel, int& comp) {
  if (j < 2) channel = k_y, comp = 4 * j + q;
  else channel = q < 2 ? k_cb : k_cr, comp = q % 2;
}

Vec3 from_parabolic(double px, double py) {
  double r2 = px * px + py * py;
  if (r2 > 1) {  // outside the hemisphere's disc: the rim (horizon) direction
    const double r = std::sqrt(r2);
    px /= r, py /= r, r2 = 1;
  }
  const double s = 1.0 / (1.0 + r2);
  return {float(2 * px * s), float(2 * py * s), float((1 - r2) * s)};
}

uint32_t nearest(const DirectionSet& set, const Vec3& d) {
  uint32_t best = 0;
  double best_dot = -INFINITY;
  for (size_t i = 0; i < set.size(); ++i) {
    const Vec3& s = set.dirs[i];
    const double dot = double(s.x) * d.x + double(s.y) * d.y + double(s.z) * d.z;
    if (dot > best_dot) best_dot = dot, best = uint32_t(i);
  }
  return best;
}

}  // namespace

Result<std::vector<Tensor>> LpyrModel::gpu_tensors() const {
  const int nl = int(m_desc.num_lights()), nv = int(m_desc.num_views()), L = lmax() + 1;
  for (const Level& lv : m_levels)
    if (lv.ch[k_y].E.cols() > 8 || lv.ch[k_cb].E.cols() > 2 || lv.ch[k_cr].E.cols() > 2)
      return unsupported(m_spec + ": the section 3.3 texture layout holds at most 8 Y and 2 Cb/Cr components per level");
  std::vector<Tensor> out;

  // Eigen-Laplacian-BRDF map: (L nV) rows x (3 nL) columns of RGBA.
  {
    const size_t W = size_t(3 * nl), H = size_t(L) * size_t(nv);
    std::vector<float> m(W * H * 4, 0.0f);
    for (int k = 0; k < L; ++k)
      for (int v = 0; v < nv; ++v)
        for (int l = 0; l < nl; ++l)
          for (int j = 0; j < 3; ++j)
            for (int q = 0; q < 4; ++q) {
              int c, comp;
              slot_source(j, q, c, comp);
              const MatrixXfR& E = m_levels[size_t(k)].ch[c].E;
              if (comp >= E.cols()) continue;
              const size_t row = size_t(k) * size_t(nv) + size_t(v), col = size_t(j) * size_t(nl) + size_t(l);
              m[(row * W + col) * 4 + size_t(q)] = E(l + nl * v, comp);
            }
    out.push_back(Tensor::from_f32("eigen_map", {H, W, 4}, m.data()));
  }

  // PCA weight map: level k's three slots nest in the previous level's fourth quadrant.
  {
    std::vector<size_t> ox(static_cast<size_t>(L)), oy(static_cast<size_t>(L));
    size_t W = 0, H = 0;
    for (int k = 0; k < L; ++k) {
      const LevelSize s = m_levels[size_t(k)].size;
      if (k > 0) {
        const LevelSize p = m_levels[size_t(k) - 1].size;
        ox[size_t(k)] = ox[size_t(k) - 1] + size_t(p.w), oy[size_t(k)] = oy[size_t(k) - 1] + size_t(p.h);
      }
      W = std::max(W, ox[size_t(k)] + 2 * size_t(s.w)), H = std::max(H, oy[size_t(k)] + 2 * size_t(s.h));
    }
    std::vector<float> m(W * H * 4, 0.0f);
    for (int k = 0; k < L; ++k) {
      const Level& lv = m_levels[size_t(k)];
      for (int j = 0; j < 3; ++j) {
        const size_t x0 = ox[size_t(k)] + (j == 1 ? size_t(lv.size.w) : 0), y0 = oy[size_t(k)] + (j == 2 ? size_t(lv.size.h) : 0);
        for (int y = 0; y < lv.size.h; ++y)
          for (int x = 0; x < lv.size.w; ++x)
            for (int q = 0; q < 4; ++q) {
              int c, comp;
              slot_source(j, q, c, comp);
              const MatrixXfR& D = lv.ch[c].D;
              if (comp >= D.cols()) continue;
              m[((y0 + size_t(y)) * W + x0 + size_t(x)) * 4 + size_t(q)] = D(x + lv.size.w * y, comp);
            }
      }
    }
    out.push_back(Tensor::from_f32("weight_map", {H, W, 4}, m.data()));
  }

  // Means added per level (zero where dropped), (Y, Cb, Cr, 0).
  {
    const size_t W = size_t(nl), H = size_t(L) * size_t(nv);
    std::vector<float> m(W * H * 4, 0.0f);
    for (int k = 0; k < L; ++k)
      for (int c = 0; c < 3; ++c) {
        const Eigen::VectorXf& mu = m_levels[size_t(k)].ch[c].mean;
        if (!mu.size()) continue;
        for (int v = 0; v < nv; ++v)
          for (int l = 0; l < nl; ++l) m[((size_t(k) * size_t(nv) + size_t(v)) * W + size_t(l)) * 4 + size_t(c)] = mu(l + nl * v);
      }
    out.push_back(Tensor::from_f32("mean_map", {H, W, 4}, m.data()));
  }

  if (m_phong) {
    const float ph[6] = {m_ph.ka, m_ph.kd, m_ph.ks, m_ph.alpha, m_chroma[0], m_chroma[1]};
    out.push_back(Tensor::from_f32("phong", {6}, ph));
  }

  {
    std::vector<uint32_t> lut(2 * k_lut_size * k_lut_size);
    for (int i = 0; i < k_lut_size; ++i)
      for (int j = 0; j < k_lut_size; ++j) {
        const double step = 2.0 / k_lut_size;
        const Vec3 d = from_parabolic(-1 + (j + 0.5) * step, -1 + (i + 0.5) * step);
        lut[size_t(i * k_lut_size + j)] = nearest(m_desc.lights, d);
        lut[size_t(k_lut_size * k_lut_size + i * k_lut_size + j)] = nearest(m_desc.views, d);
      }
    out.push_back(Tensor::from_u32("direction_lut", {2, k_lut_size, k_lut_size}, lut.data()));
  }
  return out;
}

}  // namespace btfc::lpyr
