// Direction interpolation lookup (core/interp.h): DirectionInterpolator::weights() (fine lookup
// table, fallback to the search) against weights_reference() (the search alone), per call, one
// thread, on random directions: theta uniform in [0, --theta-max] degrees, phi uniform.
//
//   bench_interp [--queries 4000000] [--theta-max 80] [--set ubo2003|ubo2014]
// Also prints, per kind of answer (fast_path_kind), its share and cost, and the constructor's time.
#include <cstdio>
#include <cstdlib>
#include <random>
#include <string>
#include <vector>

#include "bench/bench_timing.h"
#include "core/interp.h"

using namespace btfc;

using btfc::bench::now_s;

// Best of `reps` runs of f over all queries, in ns per call; `sink` keeps the results alive.
template <class F>
static double ns_per_call(const std::vector<Vec3>& q, int reps, F&& f, double& sink) {
  double best = 1e30;
  for (int r = 0; r < reps; ++r) {
    double t = now_s(), acc = 0;
    for (const Vec3& d : q) {
      const DirWeights w = f(d);
      acc += w.weight[1] + double(w.index[2]);
    }
    best = std::min(best, now_s() - t);
    sink += acc;
  }
  return best / double(q.size()) * 1e9;
}

int main(int argc, char** argv) {
  size_t nq = 4000000;
  double theta_max = 80;
  std::string set = "ubo2003";
  for (int i = 1; i + 1 < argc; i += 2) {
    std::string a = argv[i];
    if (a == "--queries") nq = size_t(std::atoll(argv[i + 1]));
    else if (a == "--theta-max") theta_max = std::atof(argv[i + 1]);
    else if (a == "--set") set = argv[i + 1];
  }
  const DirectionSet dirs = set == "ubo2014" ? DirectionSet::ubo2014() : DirectionSet::ubo2003();
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<Vec3> q(nq);
  for (Vec3& d : q) d = dir_from_theta_phi(theta_max * 3.14159265358979323846 / 180 * u(rng), 2 * 3.14159265358979323846 * u(rng));

  double t0 = now_s();
  const DirectionInterpolator in(dirs);
  (void)in.fine_grid();  // the lookup table is built on first use: include it
  const double build_ms = (now_s() - t0) * 1e3;
  size_t kinds[4] = {0, 0, 0, 0};
  for (const Vec3& d : q) ++kinds[in.fast_path_kind(d)];
  double sink = 0;
  const double fast = ns_per_call(q, 7, [&](const Vec3& d) { return in.weights(d); }, sink);
  const double ref = ns_per_call(q, 7, [&](const Vec3& d) { return in.weights_reference(d); }, sink);
  std::printf("%s (%zu directions, %zu triangles, table %d^2), %zu queries theta 0..%g deg: build %.2f ms\n",
              set.c_str(), dirs.size(), in.triangles().size(), in.fine_grid().n, nq, theta_max, build_ms);
  std::printf("  weights():           %6.2f ns/call\n", fast);
  std::printf("  weights_reference(): %6.2f ns/call  (%.1fx)\n", ref, ref / fast);
  // weights_batch in groups of 256, as FmfModel::eval_batch calls it.
  auto batch_ns = [&](const std::vector<Vec3>& v) {
    std::vector<DirWeights> out(256);
    double best = 1e30;
    for (int r = 0; r < 5; ++r) {
      const double t = now_s();
      for (size_t i = 0; i < v.size(); i += 256) {
        in.weights_batch(v.data() + i, std::min<size_t>(256, v.size() - i), out.data());
        sink += out[0].weight[1];
      }
      best = std::min(best, now_s() - t);
    }
    return best / double(v.size()) * 1e9;
  };
  std::printf("  weights_batch():     %6.2f ns/call\n", batch_ns(q));
  // Per kind of answer, on the queries of that kind alone (branches then predict well).
  const char* names[4] = {"search", "triangle", "hull edges", "candidates"};
  for (int k = 0; k < 4; ++k) {
    std::vector<Vec3> sub;
    for (const Vec3& d : q)
      if (in.fast_path_kind(d) == k) sub.push_back(d);
    if (sub.empty()) continue;
    const double t = ns_per_call(sub, 5, [&](const Vec3& d) { return in.weights(d); }, sink);
    const double tr = ns_per_call(sub, 5, [&](const Vec3& d) { return in.weights_reference(d); }, sink);
    std::printf("    %-10s %5.1f%%: weights() %6.2f ns/call, reference %6.2f, batch %6.2f\n", names[k], 100.0 * double(sub.size()) / double(nq),
                t, tr, batch_ns(sub));
  }
  std::printf("  the table answers %.1f%% of calls (%.1f%% with one triangle), the search %.1f%%  (checksum %.6g)\n",
              100.0 * double(nq - kinds[0]) / double(nq), 100.0 * double(kinds[1]) / double(nq),
              100.0 * double(kinds[0]) / double(nq), sink);
  return 0;
}
