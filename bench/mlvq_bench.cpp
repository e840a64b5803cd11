// mlvq decoding throughput (issue 7; docs/benchmarks.md): encodes a synthetic BTF (or a raw
// .btfc) with an mlvq spec, then measures decoded evaluations per second on
//  - the batched decode path (Model::decode: per texel one walk of the codebook chain over the
//    whole 4D grid, then 16-node interpolation for every measured (light, view) pair), and
//  - eval_batch on random queries at arbitrary directions (OpenCL kernel when a device works,
//    else the C++ reference), one evaluation = one RGB value at (texel, light dir, view dir).
//
//   bench_mlvq [--width 64] [--height 64] [--codec mlvq:scheme=2] [--input file.btfc] [--queries 4000000]
#include <chrono>
#include <cmath>
#include <cstdio>
#include <random>
#include <string>

#include "codecs/codec.h"
#include "core/blas_env.h"
#include "core/container.h"
#include "core/metrics.h"
#include "core/synth.h"

using namespace btfc;

static double now_s() { return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count(); }

int main(int argc, char** argv) {
  reexec_for_openblas(argc, argv);
  int width = 64, height = 64;
  size_t queries = 4000000;
  std::string spec = "mlvq:scheme=2", input;
  for (int i = 1; i < argc; ++i) {
    std::string a = argv[i];
    if (a == "--width" && i + 1 < argc) width = std::atoi(argv[++i]);
    else if (a == "--height" && i + 1 < argc) height = std::atoi(argv[++i]);
    else if (a == "--codec" && i + 1 < argc) spec = argv[++i];
    else if (a == "--input" && i + 1 < argc) input = argv[++i];
    else if (a == "--queries" && i + 1 < argc) queries = size_t(std::atoll(argv[++i]));
    else {
      std::fprintf(stderr, "unknown argument %s\n", a.c_str());
      return 1;
    }
  }
  Result<Btf> btf = Status();
  if (!input.empty()) {
    auto rd = ContainerReader::open(input);
    if (!rd.ok()) return std::fprintf(stderr, "%s\n", rd.status().message().c_str()), 2;
    btf = load_raw_btf(rd.value());
  } else {
    SynthOptions so;
    so.width = width, so.height = height;
    btf = synthesize_btf(so);
  }
  if (!btf.ok()) return std::fprintf(stderr, "%s\n", btf.status().message().c_str()), 2;
  auto r = resolve_spec(spec);
  if (!r.ok()) return std::fprintf(stderr, "%s\n", r.status().message().c_str()), 1;
  Context ctx;
  double t0 = now_s();
  auto m = r->first->encode(btf.value(), r->second, ctx);
  if (!m.ok()) return std::fprintf(stderr, "%s\n", m.status().message().c_str()), 3;
  const double enc = now_s() - t0;
  const Model& model = *m.value();
  const BtfDesc& d = btf->desc();
  std::printf("input %s; %s\n", d.summary().c_str(), spec.c_str());
  std::printf("encode %.2f s\n", enc);
  for (const auto& [k, v] : model.stats().numbers) std::printf("  %s = %.6g\n", k.c_str(), v);
  Btf out;
  const double evals = double(d.num_texels()) * double(d.num_images());
  for (int rep = 0; rep < 2; ++rep) {  // run 0 allocates (first-touch page faults), run 1 reuses the output
    t0 = now_s();
    if (!model.decode_all(out).ok()) return 3;
    const double dec = now_s() - t0;
    std::printf("decode (batched, measured directions, run %d): %.3f s, %.1f M evaluations/s (%.1f M values/s)\n", rep, dec,
                evals / dec / 1e6, evals * d.channels / dec / 1e6);
  }
  auto mt = compare_btf(btf.value(), out);
  if (mt.ok()) std::printf("quality: rmse %.6g rel_l2 %.5f psnr %.2f dB mean_ssim %.4f\n", mt->rmse, mt->rel_l2, mt->psnr, mt->mean_ssim);
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<EvalQuery> q(queries);
  for (auto& e : q) {
    e.x = int(rng() % uint32_t(d.width)), e.y = int(rng() % uint32_t(d.height));
    e.wl = dir_from_theta_phi(std::acos(u(rng)), 6.283185307 * u(rng));
    e.wv = dir_from_theta_phi(std::acos(u(rng)), 6.283185307 * u(rng));
  }
  std::vector<float> res(q.size() * size_t(d.channels));
  for (int rep = 0; rep < 2; ++rep) {  // the first run builds / uploads the kernel
    t0 = now_s();
    if (!model.eval_batch(q, res.data()).ok()) return 3;
    const double t = now_s() - t0;
    std::printf("eval_batch random directions (run %d): %.3f s, %.1f M evaluations/s\n", rep, t, double(q.size()) / t / 1e6);
  }
  return 0;
}
