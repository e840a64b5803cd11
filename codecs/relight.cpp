// Model::relight, the reference every codec has (codec.h): direct quadrature of the model's
// values over the measured light directions against an SH lighting environment. It needs only
// eval(), so a new codec relights without code of its own; lpca overrides it with the paper's
// PRT path (codecs/lpca/relight.cpp), and the two agree (tests/relight_test.cpp).
#include <algorithm>
#include <cmath>

#include "codecs/codec.h"
#include "core/interp.h"
#include "core/sh.h"

namespace btfc {

Result<std::vector<float>> Model::relight(const EnvironmentSH& env, const Vec3& view_dir) const {
  if (env.order < 1 || env.order > sh::k_max_order || env.coeffs.size() != size_t(3) * size_t(env.order) * size_t(env.order))
    return invalid_argument("environment: order " + std::to_string(env.order) + " with " + std::to_string(env.coeffs.size()) +
                            " coefficients (need order in [1, 16] and 3 x order^2 coefficients)");
  const double len = std::sqrt(double(view_dir.x) * view_dir.x + double(view_dir.y) * view_dir.y + double(view_dir.z) * view_dir.z);
  if (!(len > 0) || view_dir.z / len <= 1e-6) return invalid_argument("relight: the view direction is at or below the sample's horizon");
  const Vec3 v{float(view_dir.x / len), float(view_dir.y / len), float(view_dir.z / len)};
  const BtfDesc& d = desc();
  const int nc = d.channels, nl = int(d.num_lights());
  // Per light: its solid angle times the environment's radiance from it (RGB), i.e. everything
  // of the sum that does not depend on the texel.
  const std::vector<double> w = sh::hemisphere_cell_weights(d.lights);
  std::vector<float> lw(size_t(nl) * 3);
  for (int l = 0; l < nl; ++l) {
    const Vec3& dl = d.lights.dirs[size_t(l)];
    for (int c = 0; c < 3; ++c)
      lw[size_t(l) * 3 + size_t(c)] =
          float(w[size_t(l)] * sh::evaluate(env.order, env.coeffs.data() + size_t(c) * size_t(env.order) * size_t(env.order), dl.x, dl.y, dl.z));
  }
  const DirWeights vw = DirectionInterpolator(d.views).weights(v);
  std::vector<float> out(d.num_texels() * 3, 0.f);
#pragma omp parallel for schedule(static)
  for (int y = 0; y < d.height; ++y) {
    std::vector<float> val(size_t(std::max(nc, 1)));
    for (int x = 0; x < d.width; ++x) {
      double acc[3] = {0, 0, 0};
      for (int t = 0; t < 3; ++t) {
        const float wv = vw.weight[size_t(t)];
        if (wv == 0) continue;
        for (int l = 0; l < nl; ++l) {
          eval(x, y, l, vw.index[size_t(t)], val.data());
          for (int c = 0; c < 3; ++c) acc[c] += double(wv) * lw[size_t(l) * 3 + size_t(c)] * val[size_t(std::min(c, nc - 1))];
        }
      }
      float* o = out.data() + (size_t(y) * size_t(d.width) + size_t(x)) * 3;
      for (int c = 0; c < 3; ++c) o[c] = float(acc[c]);
    }
  }
  return out;
}

}  // namespace btfc
