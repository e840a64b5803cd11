// eval_batch's frame for codecs that blend the 3 x 3 measured (light, view) pairs around a
// query's directions on the CPU (lpca, lpyr): the queries in groups of k_eval_group over the OpenMP
// threads; a query at measured indices goes to model.eval, the others' directions are located
// together (DirectionInterpolator::weights_batch: weights()'s bits, without one call per
// direction) and handed to the codec's blend. Queries must have been checked
// (check_eval_queries).
#pragma once
#include <algorithm>
#include <cstdint>
#include <span>

#include "codecs/codec.h"
#include "core/interp.h"

namespace btfc {

constexpr size_t k_eval_group = 256;

// blend(query, light weights, view weights, out): out is the query's `channels` floats.
template <class Blend>
void eval_grouped(const Model& model, const DirectionInterpolator& lights, const DirectionInterpolator& views, std::span<const EvalQuery> q,
                  float* out, Blend&& blend) {
  constexpr size_t G = k_eval_group;
  const size_t nc = size_t(model.desc().channels);
  const long long groups = (long long)((q.size() + G - 1) / G);
#pragma omp parallel for schedule(static)
  for (long long g = 0; g < groups; ++g) {
    const size_t i0 = size_t(g) * G, m = std::min(G, q.size() - i0);
    Vec3 dl[G], dv[G];
    DirWeights wa[G], wb[G];
    uint32_t who[G];
    size_t k = 0;
    for (size_t j = 0; j < m; ++j) {
      const EvalQuery& e = q[i0 + j];
      if (e.light >= 0) model.eval(e.x, e.y, e.light, e.view, out + nc * (i0 + j));
      else dl[k] = e.wl, dv[k] = e.wv, who[k++] = uint32_t(j);
    }
    lights.weights_batch(dl, k, wa);
    views.weights_batch(dv, k, wb);
    for (size_t j = 0; j < k; ++j) blend(q[i0 + who[j]], wa[j], wb[j], out + nc * (i0 + who[j]));
  }
}

}  // namespace btfc
