// Random-access evaluation benchmark (issue 24, docs/benchmarks.md): a rank-C rgb fmf model
// with random factors in the UBO2003 layout (81 x 81 directions, 19683 rows, `--texels`
// texels), evaluated at random texels and random directions (theta uniform in 0..80 degrees,
// as `btfc bench` draws them; beyond the outermost ring at 75 degrees a direction is projected
// onto the hull), all in one run so the ratios mean something on a noisy machine:
//   - FmfModel::eval_batch from directions (the two Delaunay lookups included), C++ path;
//   - the blend alone from precomputed (index, weight) pairs, as a renderer's index / weight
//     textures give them (fmf_eval.h), with a sweep of the sorted block size;
//   - the Delaunay lookups alone;
//   - the per-query reference (Model::eval_batch: eval_dir per query), the test oracle;
//   - the OpenCL kernel on the same weighted queries, when a device is present;
//   - a coherent stream (frames of all texels under one direction pair) through eval_batch.
// With --color dfmf: a color=dfmf model instead (three channel blocks of 6561 rows, Bonn's
// offset), its eval_batch (C++ path, fmf_eval_dfmf.cpp) against the per-query reference only.
// Then every codec beside it (unless --codecs 0): each codec's default model, fmf at rank 32, of
// one BTF (--btf PATH, any input btfc reads; else btfc's synth material at 64 x 64 texels),
// its random interpolated evaluations per second through Model::eval_batch on the C++ path, as
// `btfc bench` measures them (codecs/measure.h: 131072 random queries per round, rounds for 1 s).
//
//   bench_eval [--texels 65536] [--rank 32] [--queries 4000000] [--color rgb|dfmf] [--btf PATH] [--codecs 0|1]
#include <cmath>
#include <cstdio>
#include <random>
#include <string>

#include <Imath/half.h>

#include "bench/bench_timing.h"
#include "codecs/fmf/fmf_cl.h"
#include "codecs/fmf/fmf_eval.h"
#include "codecs/fmf/fmf_model.h"
#include "codecs/measure.h"
#include "core/cl_runtime.h"
#include "core/cpu_dispatch.h"
#include "core/synth.h"
#include "formats/btf_io.h"

using namespace btfc;

using btfc::bench::best_of;
using btfc::bench::now_s;

namespace {

// The BTF of the every-codec table (the file comment): --btf's, else btfc's synth material.
Result<Btf> codec_btf(const std::string& path) {
  if (!path.empty()) return read_btf(path);
  SynthOptions so;
  so.width = so.height = 64;
  return synthesize_btf(so);
}

// Every codec's random-query rate on `btf` (the file comment): its default model (fmf at rank 32,
// the rank of the headline), C++ path.
void every_codec(const Btf& btf, const std::string& name) {
  const BtfDesc& d = btf.desc();
  std::printf("every codec's default model of %s (%d x %d texels, %zu x %zu directions): random interpolated evaluations, C++ path\n",
              name.c_str(), d.width, d.height, d.num_lights(), d.num_views());
  ocl::set_device_choice(ocl::DeviceChoice::cpu);
  BenchOptions opt;
  opt.renders = false;
  opt.throughput_seconds = 1.0;
  for (const char* spec : {"fmf:rank=32", "fmf:rank=32:color=dfmf", "lpca", "lpyr", "mlvq"}) {
    Result<BenchResult> r = run_benchmark(btf, spec, opt);
    if (!r.ok()) {
      std::printf("  %-24s %s\n", spec, r.status().message().c_str());
      continue;
    }
    std::printf("  %-24s %8.2f M evals/s   (ratio %.0f, PSNR %.1f dB, encode %.1f s)\n", spec, r.value().evals_per_second / 1e6,
                r.value().ratio, r.value().metrics.psnr, r.value().encode_seconds);
  }
}

}  // namespace

int main(int argc, char** argv) {
  int texels = 65536, C = 32;
  size_t nq = 4000000;
  bool profile = false;  // --profile 1: only the blend, repeated (for perf)
  std::string color = "rgb", precision = "half", btf_path;
  bool codecs = true;
  for (int i = 1; i + 1 < argc; i += 2) {
    std::string a = argv[i];
    if (a == "--texels") texels = std::atoi(argv[i + 1]);
    else if (a == "--rank") C = std::atoi(argv[i + 1]);
    else if (a == "--queries") nq = size_t(std::atoll(argv[i + 1]));
    else if (a == "--profile") profile = std::atoi(argv[i + 1]) != 0;
    else if (a == "--color") color = argv[i + 1];
    else if (a == "--precision") precision = argv[i + 1];
    else if (a == "--btf") btf_path = argv[i + 1];
    else if (a == "--codecs") codecs = std::atoi(argv[i + 1]) != 0;
  }
  if (color != "rgb" && color != "dfmf") {
    std::fprintf(stderr, "bench_eval: --color %s: expected rgb or dfmf\n", color.c_str());
    return 2;
  }
  // The every-codec table's BTF first, so that a bad --btf fails before the long part.
  Btf codec_input;
  if (codecs) {
    Result<Btf> r = codec_btf(btf_path);
    if (!r.ok()) {
      std::fprintf(stderr, "bench_eval: %s\n", r.status().message().c_str());
      return 1;
    }
    codec_input = std::move(r).value();
  }
  const std::string codec_name = btf_path.empty() ? "btfc synth" : btf_path;
  const int side = int(std::lround(std::sqrt(double(texels))));
  texels = side * side;
  BtfDesc desc;
  desc.width = desc.height = side;
  desc.channels = 3;
  desc.lights = desc.views = DirectionSet::ubo2003();
  std::mt19937 rng(1);
  std::uniform_real_distribution<float> u(-1, 1);
  std::uniform_real_distribution<double> u01(0, 1);
  const double max_theta = 80.0 * M_PI / 180;
  auto random_queries = [&](size_t n) {
    std::vector<EvalQuery> q(n);
    for (EvalQuery& e : q) {
      e.x = int(rng() % unsigned(side)), e.y = int(rng() % unsigned(side));
      e.wl = dir_from_theta_phi(u01(rng) * max_theta, u01(rng) * 2 * M_PI);
      e.wv = dir_from_theta_phi(u01(rng) * max_theta, u01(rng) * 2 * M_PI);
    }
    return q;
  };
  // Frames of every texel under one direction pair each (the pairs of q's first queries in turn).
  auto coherent_frames = [&](const std::vector<EvalQuery>& q) {
    std::vector<EvalQuery> cq(nq);
    for (size_t i = 0; i < nq; ++i) {
      cq[i] = q[(i / size_t(texels)) % nq];
      cq[i].x = int(i % size_t(texels)) % side, cq[i].y = int(i % size_t(texels)) / side;
    }
    return cq;
  };
  if (color == "dfmf") {
    // Random channel factors scaled so that log Y stays within a few units (a real model's range).
    std::vector<fmf::Block> blocks;
    for (const char* name : {"y", "u", "v"}) {
      fmf::Block c;
      c.name = name;
      c.U.resize(Eigen::Index(desc.num_lights() * desc.num_views()), C);
      c.SxV.resize(texels, C);
      const float g = 1.0f / std::sqrt(float(C));
      for (Eigen::Index i = 0; i < c.U.size(); ++i) {  // as a default (precision=half) model stores U, unless --precision float
        c.U.data()[i] = u(rng) * g;
        if (precision == "half") c.U.data()[i] = float(Imath::half(c.U.data()[i]));
      }
      for (Eigen::Index i = 0; i < c.SxV.size(); ++i) c.SxV.data()[i] = u(rng);
      c.S = Eigen::VectorXf::Ones(C), c.scale = Eigen::VectorXf::Ones(C);
      blocks.push_back(std::move(c));
    }
    fmf::Config dcfg;
    dcfg.dfmf = true;
    const fmf::FmfModel m(desc, "fmf:color=dfmf:rank=" + std::to_string(C), dcfg, std::move(blocks));
    std::printf("dfmf fmf, rank %d, %d x %d texels, 81 x 81 directions, %zu random queries, loops: %s\n", C, side, side, nq,
                cpu_dispatch_level());
    const std::vector<EvalQuery> q = random_queries(nq);
    std::vector<float> out(3 * nq), ref(3 * nq);
    ocl::set_device_choice(ocl::DeviceChoice::cpu);
    const double t = best_of(3, [&] { (void)m.eval_batch(q, out.data()); });
    const size_t nr = std::min<size_t>(nq, 400000);
    const double t_ref = best_of(1, [&] { (void)m.Model::eval_batch(std::span(q).first(nr), ref.data()); });
    double num = 0, den = 0;
    for (size_t i = 0; i < 3 * nr; ++i) num += double(out[i] - ref[i]) * (out[i] - ref[i]), den += double(ref[i]) * ref[i];
    std::printf("eval_batch, directions (C++ path)     %8.1f M evals/s\n", double(nq) / t / 1e6);
    std::printf("reference (eval_dir per query)        %8.1f M evals/s   fast / reference = %.1f, rel. L2 diff %.2e\n",
                double(nr) / t_ref / 1e6, (double(nq) / t) / (double(nr) / t_ref), std::sqrt(num / den));
    // Coherent frames (every texel under one direction pair per frame): the rows stay in cache,
    // so this is the path's arithmetic with little of its memory latency.
    const std::vector<EvalQuery> cq = coherent_frames(q);
    const double t_coh = best_of(3, [&] { (void)m.eval_batch(cq, out.data()); });
    std::printf("eval_batch, coherent frames           %8.1f M evals/s\n", double(nq) / t_coh / 1e6);
    // The OpenCL kernel (--device cl), when a device is present.
    ocl::set_device_choice(ocl::DeviceChoice::cl);
    if (ocl::Runtime::get().ok() && m.eval_batch(std::span(q).first(1000), out.data()).ok()) {
      const double t_cl = best_of(3, [&] { (void)m.eval_batch(q, out.data()); });
      std::printf("eval_batch through OpenCL (%s)       %8.1f M evals/s\n", ocl::Runtime::get().value()->info().type.c_str(),
                  double(nq) / t_cl / 1e6);
    } else {
      std::printf("OpenCL: no device\n");
    }
    if (codecs) every_codec(codec_input, codec_name);
    return 0;
  }
  fmf::Block b;
  b.name = "rgb";
  b.U.resize(Eigen::Index(desc.abrdf_size()), C);
  b.SxV.resize(texels, C);
  // U's values as a default (precision=half) model stores them, unless --precision float.
  for (Eigen::Index i = 0; i < b.U.size(); ++i) b.U.data()[i] = precision == "half" ? float(Imath::half(u(rng))) : u(rng);
  for (Eigen::Index i = 0; i < b.SxV.size(); ++i) b.SxV.data()[i] = u(rng);
  b.S = Eigen::VectorXf::Ones(C), b.scale = Eigen::VectorXf::Ones(C);
  fmf::Config cfg;
  std::vector<fmf::Block> blocks{b};
  fmf::FmfModel model(desc, "fmf:rank=" + std::to_string(C), cfg, std::move(blocks));
  std::printf("rgb fmf, rank %d, %d x %d texels, 81 x 81 directions, %zu random queries, loops: %s\n", C, side, side, nq,
              cpu_dispatch_level());

  std::vector<EvalQuery> q = random_queries(nq);
  std::vector<float> out(3 * nq), ref(3 * nq);
  auto rate = [&](double t) { return double(nq) / t / 1e6; };

  ocl::set_device_choice(ocl::DeviceChoice::cpu);
  (void)model.eval_batch(std::span(q).first(std::min<size_t>(nq, 100000)), out.data());
  const double t_batch = best_of(3, [&] { (void)model.eval_batch(q, out.data()); });
  std::printf("eval_batch, directions (C++ path)     %8.1f M evals/s\n", rate(t_batch));

  // The weights alone, and the blend alone on them.
  DirectionInterpolator interp(desc.lights);
  std::vector<btfc_fmf_query> wq(nq);
  const double t_single = best_of(3, [&] {
#pragma omp parallel for schedule(static)
    for (size_t i = 0; i < nq; ++i) {
      DirWeights a = interp.weights(q[i].wl), c = interp.weights(q[i].wv);
      btfc_fmf_query& k = wq[i];
      k.texel = q[i].x + side * q[i].y;
      for (int j = 0; j < 3; ++j) k.light[j] = a.index[j], k.view[j] = c.index[j], k.wl[j] = a.weight[j], k.wv[j] = c.weight[j];
    }
  });
  std::printf("Delaunay lookups alone, weights()     %8.1f M queries/s (2 per query)\n", rate(t_single));
  // In groups of 256 queries, as eval_batch locates them (weights_batch).
  const double t_weights = best_of(3, [&] {
    constexpr size_t G = 256;
#pragma omp parallel for schedule(static)
    for (size_t i0 = 0; i0 < nq; i0 += G) {
      const size_t m = std::min(G, nq - i0);
      Vec3 dl[G], dv[G];
      DirWeights a[G], c[G];
      for (size_t j = 0; j < m; ++j) dl[j] = q[i0 + j].wl, dv[j] = q[i0 + j].wv;
      interp.weights_batch(dl, m, a);
      interp.weights_batch(dv, m, c);
      for (size_t j = 0; j < m; ++j) {
        btfc_fmf_query& k = wq[i0 + j];
        k.texel = q[i0 + j].x + side * q[i0 + j].y;
        for (int l = 0; l < 3; ++l)
          k.light[l] = a[j].index[l], k.view[l] = c[j].index[l], k.wl[l] = a[j].weight[l], k.wv[l] = c[j].weight[l];
      }
    }
  });
  std::printf("Delaunay lookups alone, weights_batch %8.1f M queries/s (2 per query)\n", rate(t_weights));
  const fmf::EvalFactors f = model.eval_factors();  // as eval_batch reads them (huge pages)
  if (profile) {
    const double t = best_of(20, [&] { fmf::eval_weighted(f, wq, out.data()); });
    std::printf("blend alone %.1f M evals/s\n", rate(t));
    return 0;
  }
  const double t_blend = best_of(3, [&] { fmf::eval_weighted(f, wq, out.data()); });
  std::printf("blend alone, weighted queries         %8.1f M evals/s (block %zu)\n", rate(t_blend), fmf::k_eval_block);
  for (size_t block : {size_t(1024), size_t(4096), size_t(16384), size_t(65536), size_t(262144), size_t(1) << 20}) {
    const double t = best_of(3, [&] {
      const size_t nb = (nq + block - 1) / block;
#pragma omp parallel for schedule(dynamic, 1)
      for (size_t i = 0; i < nb; ++i) {
        const size_t b0 = i * block;
        fmf::eval_weighted_block(f, wq.data() + b0, std::min(block, nq - b0), out.data() + 3 * b0);
      }
    });
    std::printf("  block %6zu%s                    %8.1f M evals/s\n", block, "           ", rate(t));
  }

  // The per-query reference on a slice (it is slow), and the relative difference.
  const size_t nr = std::min<size_t>(nq, 400000);
  const double t_ref = best_of(1, [&] { (void)model.Model::eval_batch(std::span(q).first(nr), ref.data()); });
  double num = 0, den = 0;
  (void)model.eval_batch(q, out.data());
  for (size_t i = 0; i < 3 * nr; ++i) num += double(out[i] - ref[i]) * (out[i] - ref[i]), den += double(ref[i]) * ref[i];
  std::printf("reference (eval_dir per query)        %8.1f M evals/s   fast / reference = %.1f, rel. L2 diff %.2e\n",
              double(nr) / t_ref / 1e6, (double(nq) / t_batch) / (double(nr) / t_ref),
              std::sqrt(num / den));

  // OpenCL on the same weighted queries.
  ocl::set_device_choice(ocl::DeviceChoice::automatic);
  if (ocl::Runtime::get().ok()) {
    fmf_cl::PackedFactors pf;
    pf.mode = BTFC_FMF_RGB, pf.blocks = 1, pf.C = C, pf.nL = 81, pf.nV = 81, pf.texels = texels, pf.rows_per_block = 3 * 81 * 81;
    pf.U.assign(f.U, f.U + size_t(pf.rows_per_block) * C);
    pf.SxV.assign(f.SxV, f.SxV + size_t(texels) * C);
    auto dev = fmf_cl::DeviceFactors::upload(pf);
    if (dev.ok()) {
      (void)dev.value()->eval_interp(std::span(wq).first(1000), out.data());
      const double t = best_of(3, [&] { (void)dev.value()->eval_interp(wq, out.data()); });
      std::printf("OpenCL fmf_eval_interp (%s)  %8.1f M evals/s\n", ocl::Runtime::get().value()->info().type.c_str(), rate(t));
    }
  } else {
    std::printf("OpenCL: no device\n");
  }

  // Coherent: frames of every texel under one direction pair each.
  ocl::set_device_choice(ocl::DeviceChoice::cpu);
  const std::vector<EvalQuery> cq = coherent_frames(q);
  const double t_coh = best_of(3, [&] { (void)model.eval_batch(cq, out.data()); });
  std::printf("eval_batch, coherent frames           %8.1f M evals/s\n", rate(t_coh));
  // The same two streams through the OpenCL path of eval_batch (--device cl), when present.
  ocl::set_device_choice(ocl::DeviceChoice::cl);
  if (ocl::Runtime::get().ok()) {
    (void)model.eval_batch(std::span(q).first(std::min<size_t>(nq, 100000)), out.data());
    const double t_r = best_of(3, [&] { (void)model.eval_batch(q, out.data()); });
    const double t_c = best_of(3, [&] { (void)model.eval_batch(cq, out.data()); });
    std::printf("eval_batch on OpenCL (%s): random %.1f, coherent %.1f M evals/s\n", ocl::Runtime::get().value()->info().type.c_str(),
                rate(t_r), rate(t_c));
  }
  if (codecs) every_codec(codec_input, codec_name);
  return 0;
}
