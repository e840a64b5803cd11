// lpca and lpyr OpenCL kernels on PoCL against their C++ references (docs/benchmarks.md), in
// one run so the ratios are meaningful on a noisy machine.
//
//   bench_cl_codecs [--texels 8192] [--clusters 32] [--components 8] [--candidates 6] [--side 128]
// lpca assignment: projections of texels of UBO2003 size (81 x 81 x 3 = 19683 values) in groups
// of 8, each group against `candidates` of the K clusters' c + 1 vectors (the pruned step scores
// ~2.5-7 of 31); the reference is the codec's CPU path (the same loops in C++). lpca
// relighting: 256 x 256 texels.
// lpyr: one reduce + subtract_up of a side x side level with 81 x 81 values per texel.
#include <Eigen/Core>
#include <cstdio>
#include <random>
#include <string>

#include "bench/bench_timing.h"
#include "codecs/lpca/lpca_cl.h"
#include "codecs/lpyr/lpyr_cl.h"
#include "codecs/lpyr/lpyr_internal.h"
#include "core/cl_runtime.h"

using namespace btfc;

using btfc::bench::best_of;
using btfc::bench::now_s;

static void report(const char* name, double t_cl, double t_ref, double units, const char* unit) {
  std::printf("%-26s PoCL %9.2f %s/s   C++ reference %9.2f %s/s   PoCL / C++ = %.2f\n", name, units / t_cl, unit, units / t_ref,
              unit, t_ref / t_cl);
}

int main(int argc, char** argv) {
  int N = 8192, K = 32, c = 8, side = 128, cand = 6;
  for (int i = 1; i + 1 < argc; i += 2) {
    std::string a = argv[i];
    if (a == "--texels") N = std::atoi(argv[i + 1]);
    else if (a == "--clusters") K = std::atoi(argv[i + 1]);
    else if (a == "--components") c = std::atoi(argv[i + 1]);
    else if (a == "--side") side = std::atoi(argv[i + 1]);
    else if (a == "--candidates") cand = std::atoi(argv[i + 1]);
  }
  auto rt = ocl::Runtime::get();
  if (!rt.ok()) {
    std::printf("no OpenCL device: %s\n", rt.status().message().c_str());
    return 1;
  }
  std::printf("device: %s\n", rt.value()->info().name.c_str());
  std::mt19937 rng(1);
  std::uniform_real_distribution<float> u(0, 1);

  {  // lpca assignment step: groups of 8 texels, each scored against `cand` candidate clusters
    const int d = 81 * 81 * 3, M = K * (c + 1);
    std::vector<float> X(size_t(d) * N), W(size_t(d) * M);
#pragma omp parallel for schedule(static)
    for (size_t i = 0; i < X.size(); ++i) X[i] = float((i * 2654435761u) % 1000) * 1e-3f;
    for (float& w : W) w = u(rng) - 0.5f;
    lpca_cl::ProjectionTable table;
    lpca_cl::fill_projection_table(W.data(), d, K, c, table);
    lpca_cl::GroupBatch b;
    b.X = X.data(), b.nt = N;
    b.cand_off.push_back(0);
    for (int g = 0; g < N / 8; ++g) {  // texels scattered over the range, as the codec's sorted groups are
      for (int i = 0; i < 8; ++i) b.texels.push_back(uint32_t((size_t(g) * 8 + size_t(i)) * 2654435761u % size_t(N)));
      for (int j = 0; j < cand; ++j) b.cand.push_back(uint32_t((g + j * 7) % K));
      b.cand_off.push_back(uint32_t(b.cand.size()));
    }
    std::vector<float> P(b.cand.size() * 8 * size_t(table.V));
    (void)lpca_cl::project_cl(table, b, P.data());  // warm-up: program build
    const double tc = best_of(3, [&] { (void)lpca_cl::project_cl(table, b, P.data()); });
    const double tr = best_of(3, [&] { lpca_cl::project_reference(table, b, P.data()); });
    const double gflop = 2.0 * double(N / 8 * 8) * d * cand * (c + 1) / 1e9;
    std::printf("lpca assignment: %d texels x %d values, %d of %d clusters x (%d + 1) vectors each = %.1f GFLOP\n", N, d, cand, K, c, gflop);
    report("lpca_project", tc, tr, gflop, "GFLOP");
  }
  {  // lpca relighting of a 256 x 256 image
    const size_t n = 65536, rows = size_t(K) * (c + 1);
    std::vector<uint32_t> cl_of(n);
    std::vector<float> W(n * size_t(c)), L(rows * 3), out(3 * n);
    for (auto& v : cl_of) v = uint32_t(rng() % K);
    for (float& x : W) x = u(rng);
    for (float& x : L) x = u(rng);
    (void)lpca_cl::relight_cl(cl_of, W.data(), c, L.data(), rows, out.data());
    const double tc = best_of(20, [&] { (void)lpca_cl::relight_cl(cl_of, W.data(), c, L.data(), rows, out.data()); });
    const double tr = best_of(20, [&] { lpca_cl::relight_reference(cl_of, W.data(), c, L.data(), out.data()); });
    report("lpca_relight (256^2)", tc, tr, double(n) / 1e6, "M texels");
  }
  {  // lpyr: one level
    const size_t d = 81 * 81, n = size_t(side) * side, n2 = size_t((side + 1) / 2) * ((side + 1) / 2);
    std::vector<float> f(n * d), next(n2 * d);
#pragma omp parallel for schedule(static)
    for (size_t i = 0; i < f.size(); ++i) f[i] = float((i * 2654435761u) % 1000) * 1e-3f;
    (void)lpyr::reduce_cl(f.data(), side, side, d, next.data());
    (void)lpyr::subtract_up_cl(f.data(), side, side, d, next.data());
    double tc = best_of(3, [&] { (void)lpyr::reduce_cl(f.data(), side, side, d, next.data()); });
    double tr = best_of(3, [&] { lpyr::reduce(f.data(), side, side, d, next.data()); });
    std::printf("lpyr level %d x %d, %zu values per texel (%.2f GB)\n", side, side, d, double(f.size()) * 4 / 1e9);
    report("lpyr_reduce", tc, tr, double(n) * d * 4 / 1e9, "GB read");
    // subtract_up runs in place; repeating it only changes the values, not the cost.
    tc = best_of(3, [&] { (void)lpyr::subtract_up_cl(f.data(), side, side, d, next.data()); });
    tr = best_of(3, [&] { lpyr::subtract_up(f.data(), side, side, d, next.data()); });
    report("lpyr_subtract_up", tc, tr, double(n) * d * 4 / 1e9, "GB read");
  }
  return 0;
}
