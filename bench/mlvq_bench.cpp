// mlvq encode time, payload breakdown and decoding throughput (issues 7, 22; docs/benchmarks.md):
// encodes a synthetic BTF, or any BTF btfc reads (--input: image set, raw .btfc, Bonn .btf;
// --crop x,y,w,h takes a texel rectangle of it), with a codec spec, prints the encode time and
// the model's stats (for mlvq: entries per codebook, thresholds, bytes per stored tensor), then
// measures decoded evaluations per second on
//  - the batched decode path (Model::decode: per texel one walk of the codebook chain over the
//    whole 4D grid, then 16-node interpolation for every measured (light, view) pair), and
//  - eval_batch on random queries at arbitrary directions (OpenCL kernel when a device works,
//    else the C++ reference), one evaluation = one RGB value at (texel, light dir, view dir);
//    --queries 0 skips it.
// --write-ref / --write-decoded save the input and the decoded BTF as raw .btfc files for an
// independent metric (scripts/mssim.py).
//
//   bench_mlvq [--width 64] [--height 64] [--codec mlvq:scheme=2] [--input BTF] [--crop x,y,w,h]
//              [--queries 4000000] [--write-ref ref.btfc] [--write-decoded dec.btfc]
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>
#include <string>

#include "bench/bench_timing.h"
#include "codecs/codec.h"
#include "core/blas_env.h"
#include "core/container.h"
#include "core/metrics.h"
#include "core/synth.h"
#include "formats/btf_io.h"

using namespace btfc;

using btfc::bench::now_s;

int main(int argc, char** argv) {
  reexec_for_openblas(argc, argv);
  int width = 64, height = 64;
  size_t queries = 4000000;
  std::string spec = "mlvq:scheme=2", input, crop, write_ref, write_dec;
  for (int i = 1; i < argc; ++i) {
    std::string a = argv[i];
    if (a == "--width" && i + 1 < argc) width = std::atoi(argv[++i]);
    else if (a == "--height" && i + 1 < argc) height = std::atoi(argv[++i]);
    else if (a == "--codec" && i + 1 < argc) spec = argv[++i];
    else if (a == "--input" && i + 1 < argc) input = argv[++i];
    else if (a == "--queries" && i + 1 < argc) queries = size_t(std::atoll(argv[++i]));
    else if (a == "--crop" && i + 1 < argc) crop = argv[++i];
    else if (a == "--write-ref" && i + 1 < argc) write_ref = argv[++i];
    else if (a == "--write-decoded" && i + 1 < argc) write_dec = argv[++i];
    else {
      std::fprintf(stderr, "unknown argument %s\n", a.c_str());
      return 1;
    }
  }
  Result<Btf> btf = Status();
  if (!input.empty()) {
    btf = read_btf(input);
  } else {
    SynthOptions so;
    so.width = width, so.height = height;
    btf = synthesize_btf(so);
  }
  if (!btf.ok()) return std::fprintf(stderr, "%s\n", btf.status().message().c_str()), 2;
  if (!crop.empty()) {
    int x0 = 0, y0 = 0, cw = 0, ch = 0;
    if (std::sscanf(crop.c_str(), "%d,%d,%d,%d", &x0, &y0, &cw, &ch) != 4 || x0 < 0 || y0 < 0 || cw < 1 || ch < 1 ||
        x0 + cw > btf->desc().width || y0 + ch > btf->desc().height)
      return std::fprintf(stderr, "--crop %s: not x,y,w,h inside the BTF\n", crop.c_str()), 1;
    BtfDesc cd = btf->desc();
    cd.width = cw, cd.height = ch;
    auto c = Btf::create(cd);
    if (!c.ok()) return std::fprintf(stderr, "%s\n", c.status().message().c_str()), 2;
    for (int y = 0; y < ch; ++y)
      for (int x = 0; x < cw; ++x)
        std::copy_n(btf->abrdf(size_t(x0 + x) + size_t(btf->desc().width) * size_t(y0 + y)), cd.abrdf_size(),
                    c->abrdf(size_t(x) + size_t(cw) * size_t(y)));
    btf = std::move(c);
  }
  if (!write_ref.empty() && !save_raw_btf(btf.value(), write_ref).ok()) return std::fprintf(stderr, "cannot write %s\n", write_ref.c_str()), 2;
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
  if (!write_dec.empty() && !save_raw_btf(out, write_dec).ok()) return std::fprintf(stderr, "cannot write %s\n", write_dec.c_str()), 2;
  std::printf("payload %llu bytes, ratio vs float32 %.1f, vs half %.1f\n", (unsigned long long)model.payload_bytes(),
              double(d.num_values()) * 4 / double(model.payload_bytes()), double(d.num_values()) * 2 / double(model.payload_bytes()));
  auto mt = compare_btf(btf.value(), out);
  if (mt.ok()) std::printf("quality: rmse %.6g rel_l2 %.5f psnr %.2f dB mean_ssim %.4f\n", mt->rmse, mt->rel_l2, mt->psnr, mt->mean_ssim);
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> u(0, 1);
  if (queries == 0) return 0;
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
