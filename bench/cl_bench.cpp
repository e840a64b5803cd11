// OpenCL kernel benchmark (docs/benchmarks.md): every fmf kernel on PoCL against its C++
// reference, in one run, so the ratio is meaningful on a noisy machine.
//
//   bench_cl [--texels 65536] [--rank 32] [--queries 4000000]
// Factors: random, UBO2003 directions (81 x 81, 19683 rgb rows), `--texels` texels, rank C.
// Interpolated queries get their 3 + 3 (index, weight) pairs from core/interp.h beforehand, as a
// renderer reads them from its index / weight textures; that host cost is reported separately.
#include <cstdio>
#include <cstring>
#include <random>
#include <string>

#include <Eigen/Core>

#include "bench/bench_timing.h"
#include "codecs/fmf/fmf_cl.h"
#include "core/cl_runtime.h"
#include "core/interp.h"

using namespace btfc;

using btfc::bench::best_of;
using btfc::bench::now_s;

int main(int argc, char** argv) {
  int texels = 65536, C = 32;
  size_t nq = 4000000;
  for (int i = 1; i + 1 < argc; i += 2) {
    std::string a = argv[i];
    if (a == "--texels") texels = std::atoi(argv[i + 1]);
    else if (a == "--rank") C = std::atoi(argv[i + 1]);
    else if (a == "--queries") nq = size_t(std::atoll(argv[i + 1]));
  }
  auto rt = ocl::Runtime::get();
  if (!rt.ok()) {
    std::printf("no OpenCL device: %s\n", rt.status().message().c_str());
    return 1;
  }
  std::printf("device: %s; rank %d, %d texels, 81 x 81 directions, %zu queries\n", rt.value()->info().name.c_str(), C, texels, nq);
  const DirectionSet dirs = DirectionSet::ubo2003();
  std::mt19937 rng(1);
  std::uniform_real_distribution<float> u(-1, 1);
  fmf_cl::PackedFactors f;
  f.mode = BTFC_FMF_RGB, f.blocks = 1, f.C = C, f.nL = 81, f.nV = 81, f.texels = texels, f.rows_per_block = 3 * 81 * 81;
  f.U.resize(size_t(f.rows_per_block) * C);
  f.SxV.resize(size_t(texels) * C);
  for (float& x : f.U) x = u(rng);
  for (float& x : f.SxV) x = u(rng);

  std::vector<fmf_cl::MeasuredQuery> mq(nq);
  std::vector<btfc_fmf_query> iq(nq);
  std::vector<Vec3> wl(nq), wv(nq);
  for (size_t i = 0; i < nq; ++i) {
    mq[i] = {int(rng() % texels), int(rng() % 81), int(rng() % 81), 0};
    wl[i] = dir_from_theta_phi(1.3 * (rng() % 10000) / 10000.0, 6.283 * (rng() % 10000) / 10000.0);
    wv[i] = dir_from_theta_phi(1.3 * (rng() % 10000) / 10000.0, 6.283 * (rng() % 10000) / 10000.0);
    iq[i].texel = int(rng() % texels);
  }
  DirectionInterpolator interp(dirs);
  const double t_weights = best_of(1, [&] {
#pragma omp parallel for schedule(static)
    for (size_t i = 0; i < nq; ++i) {
      DirWeights a = interp.weights(wl[i]), b = interp.weights(wv[i]);
      for (int j = 0; j < 3; ++j) iq[i].light[j] = a.index[j], iq[i].view[j] = b.index[j], iq[i].wl[j] = a.weight[j], iq[i].wv[j] = b.weight[j];
    }
  });
  std::printf("host direction weights (Delaunay lookup, 2 per query): %.1f M queries/s\n", nq / t_weights / 1e6);

  auto dev = fmf_cl::DeviceFactors::upload(f);
  if (!dev.ok()) return 1;
  std::vector<float> out(3 * nq);
  auto report = [&](const char* name, double t_cl, double t_ref, double units, const char* unit) {
    std::printf("%-22s PoCL %8.1f M %s/s   C++ reference %8.1f M %s/s   PoCL / C++ = %.2f\n", name, units / t_cl / 1e6, unit,
                units / t_ref / 1e6, unit, t_ref / t_cl);
  };
  (void)dev.value()->eval_interp(std::span(iq).first(1000), out.data());  // warm up: program build
  (void)dev.value()->eval_measured(std::span(mq).first(1000), out.data());
  double tc = best_of(3, [&] { (void)dev.value()->eval_interp(iq, out.data()); });
  double tr = best_of(3, [&] { fmf_cl::eval_interp_reference(f, iq, out.data()); });
  report("fmf_eval_interp", tc, tr, double(nq), "evals");
  // Coherent stream, as a renderer issues it: whole images of texels (in scan order) under one
  // (light, view) direction pair each, the pair changing per image.
  std::vector<btfc_fmf_query> cq(nq);
  for (size_t i = 0; i < nq; ++i) {
    const size_t img = i / size_t(texels);
    cq[i] = iq[img % nq];
    cq[i].texel = int(i % size_t(texels));
  }
  tc = best_of(3, [&] { (void)dev.value()->eval_interp(cq, out.data()); });
  tr = best_of(3, [&] { fmf_cl::eval_interp_reference(f, cq, out.data()); });
  report("fmf_eval_interp coh.", tc, tr, double(nq), "evals");
  // The same coherent stream through the grouped batch path: runs sharing a direction pair are
  // detected and evaluated by blending the pair's 9 rows once (fmf_cl.h eval_batch).
  tc = best_of(3, [&] { (void)dev.value()->eval_batch(cq, out.data()); });
  tr = best_of(3, [&] { fmf_cl::eval_batch_reference(f, cq, out.data()); });
  report("fmf_eval_batch coh.", tc, tr, double(nq), "evals");
  // The renderer's call: one direction pair, a whole frame of texels (eval_pair).
  {
    std::vector<int> frame(static_cast<size_t>(texels));
    for (int t = 0; t < texels; ++t) frame[size_t(t)] = t;
    const size_t frames = std::max<size_t>(1, nq / size_t(texels));
    (void)dev.value()->eval_pair(iq[0], frame, out.data());
    tc = best_of(3, [&] {
      for (size_t fr = 0; fr < frames; ++fr) (void)dev.value()->eval_pair(iq[fr], frame, out.data());
    });
    tr = best_of(3, [&] {
      for (size_t fr = 0; fr < frames; ++fr) fmf_cl::eval_pair_reference(f, iq[fr], frame, out.data());
    });
    report("fmf_eval_pair frames", tc, tr, double(frames * size_t(texels)), "evals");
  }
  tc = best_of(3, [&] { (void)dev.value()->eval_measured(mq, out.data()); });
  tr = best_of(3, [&] { fmf_cl::eval_measured_reference(f, mq, out.data()); });
  report("fmf_eval_measured", tc, tr, double(nq), "evals");

  // Decode: 4096 texels x all 19683 rows (80.6 M values).
  std::vector<int> tex(4096), lights(81), views(81);
  for (int i = 0; i < 4096; ++i) tex[size_t(i)] = int(rng() % texels);
  for (int i = 0; i < 81; ++i) lights[size_t(i)] = views[size_t(i)] = i;
  std::vector<float> dec(size_t(4096) * 19683);
  (void)dev.value()->decode(std::span(tex).first(16), lights, views, dec.data());
  tc = best_of(3, [&] { (void)dev.value()->decode(tex, lights, views, dec.data()); });
  tr = best_of(3, [&] { fmf_cl::decode_reference(f, tex, lights, views, dec.data()); });
  report("fmf_decode_rgb", tc, tr, double(dec.size()), "values");
  // The model's CPU decode path is not the per-value reference but one Eigen GEMM per texel
  // block (codecs/fmf/fmf.cpp): the fair yardstick for the decode kernel.
  using MatR = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  Eigen::Map<const MatR> U(f.U.data(), f.rows_per_block, C);
  MatR SX(4096, C);
  for (int i = 0; i < 4096; ++i) SX.row(i) = Eigen::Map<const MatR>(f.SxV.data(), texels, C).row(tex[size_t(i)]);
  Eigen::Map<MatR> D(dec.data(), 4096, f.rows_per_block);
  const double te = best_of(3, [&] { D.noalias() = SX * U.transpose(); });
  report("fmf_decode vs Eigen", tc, te, double(dec.size()), "values");
  return 0;
}
