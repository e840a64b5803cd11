// fmf factorization benchmark (issue: foundation; docs/benchmarks.md).
//
// Synthesizes a BTF (default: the Bonn UBO2003 size, 256 x 256 texels x 81 x 81 directions x RGB
// = 1.29 G values, 5.2 GB float32), then factorizes it with `fmf` and reports wall time, peak
// resident memory relative to the input, the GEMM rate achieved, and the relative L2 error
// against a converged reference factorization (randomized SVD with many power iterations and a
// large sketch, whose error is the Eckart-Young optimum to the printed digits; the exact
// Gram path would need a 19683^2 eigen-decomposition).
//
//   bench_fmf [--width 256] [--height 256] [--rank 32] [--power-iters 4] [--oversample 16]
//             [--reference] [--dump FILE]   (FILE: raw float32 matrix for bench/peer_sklearn.sh)
//             [--codec SPEC [--keep-input]]  (time another codec's encode on the same input instead,
//             e.g. lpyr; the encode may consume the input as `btfc compress` lets it (Context::
//             consumable), unless --keep-input)
//             [--load FILE [--rows 19683] [--texels N]]  (factorize a --dump file, or its first N
//             texels, instead of synthesizing; with --codec: the whole file as the BTF the
//             synth would have made, --width x --height texels)
//             [--scheme krylov|power] [--svd-only]  (randomized scheme; skip the codec run)
//             [--dump-only]  (with --dump or --dump-dfmf: stop after writing the files)
//             [--dump-dfmf PREFIX]  (color=dfmf's three channel matrices, automatic offset, as
//             PREFIX.y.f32, PREFIX.u.f32, PREFIX.v.f32: for bench/peer_sklearn_dfmf.sh)
//             [--dense-start]  (krylov: a Gaussian first block instead of the sparse sign sketch)
//             [--seed 1]  (the test matrix's seed)
//             [--streamed K [--chunk N]]  (with --load: the out-of-core SVD, codecs/fmf/ooc_svd.h,
//             over chunks of N texels mapped from memory as a raw .btfc's are from the page
//             cache, holding K Krylov blocks, 0 = all; the MPI path runs the same passes. N
//             defaults to the CLI's largest chunk: whole scan lines of 256 texels within 64 M
//             values, codecs/streaming.cpp)
#include <sys/resource.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "bench/bench_timing.h"
#include "codecs/codec.h"
#include "codecs/fmf/fmf.h"
#include "codecs/fmf/ooc_svd.h"
#include "core/svd.h"
#include "core/cl_runtime.h"
#include "core/blas_env.h"
#include "core/synth.h"

using namespace btfc;

using btfc::bench::now_s;
static double peak_rss_gb() {
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  return double(ru.ru_maxrss) * 1024.0 / 1e9;
}

int main(int argc, char** argv) {
  reexec_for_openblas(argc, argv);
  int width = 256, height = 256, rank = 32, power = 4, over = 16;
  bool reference = false, svd_only = false, dump_only = false, keep_input = false;
  size_t load_rows = 19683, load_texels = 0;
  RandomizedScheme scheme = RandomizedScheme::block_krylov;
  bool dense_start = false;
  uint64_t seed = 1;
  int streamed = -1, chunk = 0;
  std::string dump, dump_dfmf, codec_spec, load;
  for (int i = 1; i < argc; ++i) {
    std::string a = argv[i];
    auto next = [&] { return i + 1 < argc ? std::atoi(argv[++i]) : 0; };
    if (a == "--width") width = next();
    else if (a == "--height") height = next();
    else if (a == "--rank") rank = next();
    else if (a == "--power-iters") power = next();
    else if (a == "--oversample") over = next();
    else if (a == "--reference") reference = true;
    else if (a == "--dump" && i + 1 < argc) dump = argv[++i];
    else if (a == "--dump-dfmf" && i + 1 < argc) dump_dfmf = argv[++i];
    else if (a == "--codec" && i + 1 < argc) codec_spec = argv[++i];
    else if (a == "--load" && i + 1 < argc) load = argv[++i];
    else if (a == "--rows") load_rows = size_t(next());
    else if (a == "--texels") load_texels = size_t(next());
    else if (a == "--svd-only") svd_only = true;
    else if (a == "--keep-input") keep_input = true;
    else if (a == "--dump-only") dump_only = true;
    else if (a == "--dense-start") dense_start = true;
    else if (a == "--seed") seed = uint64_t(next());
    else if (a == "--streamed") streamed = next();
    else if (a == "--chunk") chunk = std::max(1, next());  // texels
    else if (a == "--scheme" && i + 1 < argc) scheme = std::string(argv[++i]) == "power" ? RandomizedScheme::power : RandomizedScheme::block_krylov;
    else {
      std::fprintf(stderr, "unknown argument %s\n", a.c_str());
      return 1;
    }
  }
  auto run_svd = [&](const float* B, size_t m, size_t n, double input_gb, int q, int p, const char* label) {
    SvdOptions opt;
    opt.max_rank = rank, opt.power_iters = q, opt.oversample = p, opt.method = SvdMethod::randomized, opt.scheme = scheme;
    opt.sparse_sketch = !dense_start, opt.seed = seed;
    double t = now_s();
    auto r = truncated_svd(B, m, n, opt);
    const double secs = now_s() - t;
    if (!r.ok()) {
      std::fprintf(stderr, "%s\n", r.status().message().c_str());
      std::exit(3);
    }
    // Passes over B: 2q + 2 for power, 2 per block for krylov; power's GEMMs all of width l =
    // rank + oversample, krylov's sketch (unless sparse: one add per element) and first B^T Q
    // of width l, its later passes of width min(l, rank) from q 2 on (svd.h later_krylov_width).
    const bool power = scheme == RandomizedScheme::power;
    const int passes = power ? 2 * q + 2 : 2 * r->iterations;
    const bool sparse = r->sparse_start;
    const int gemms = passes - (sparse ? 1 : 0);
    const double l = double(rank + p), lk = double(later_krylov_width(q + 1, rank + p, rank));
    const double cols = power ? gemms * l : (sparse ? 0 : l) + l + (passes - 2) * lk;
    const double flops = 2.0 * double(m) * double(n) * cols;
    std::printf(
        "%-10s rank %d q %d p %d %s: %.2f s, rel L2 error %.6f, %d passes (%d GEMMs), %.0f GFLOP/s over the whole run, peak RSS %.2f GB "
        "(%.2f x input)\n",
        label, rank, q, p, power ? "power" : (sparse ? "krylov" : "krylov_dense"), secs, r->rel_error_estimate(), passes, gemms,
        flops / secs / 1e9, peak_rss_gb(), peak_rss_gb() / input_gb);
    std::fflush(stdout);
    return r->rel_error_estimate();
  };
  // The streamed SVD over mapped in-memory chunks of `chunk` texels.
  auto run_streamed = [&](const float* B, size_t m, size_t n, double input_gb) {
    const size_t lines = std::max<size_t>(1, (size_t(64) << 20) / (m * 256));
    const MatrixChunks src(B, m, n, chunk > 0 ? size_t(chunk) : lines * 256);
    SvdOptions opt;
    opt.max_rank = rank, opt.power_iters = power, opt.oversample = over, opt.seed = seed;
    Collective one;
    StreamStats st;
    const double t = now_s();
    auto r = fmf::streaming_svd(src, owned_chunks(src, 0, 1), opt, one, &st, streamed);
    const double secs = now_s() - t;
    if (!r.ok()) {
      std::fprintf(stderr, "%s\n", r.status().message().c_str());
      std::exit(3);
    }
    const std::string variant = streamed == 0 ? "krylov" : "window" + std::to_string(streamed);
    std::printf("streamed   rank %d q %d p %d %s: %.2f s, rel L2 error %.6f, %d passes (%d blocks), chunks of %zu texels, peak RSS %.2f GB (%.2f x input)\n",
                rank, power, over, variant.c_str(), secs, r->rel_error_estimate(), st.passes, r->iterations, src.chunk_count(0), peak_rss_gb(),
                peak_rss_gb() / input_gb);
    std::printf("           pass seconds:");
    for (double p : st.pass_seconds) std::printf(" %.2f", p);
    std::printf("\n");
    std::fflush(stdout);
  };
  // --codec: time another codec's encode of `btf` (the whole encode() call).
  auto run_codec = [&](Btf& btf) {
    const BtfDesc& d = btf.desc();
    const double input_gb = double(d.num_values()) * 4 / 1e9;
    auto spec = resolve_spec(codec_spec);
    if (!spec.ok()) {
      std::fprintf(stderr, "%s\n", spec.status().message().c_str());
      return 1;
    }
    Context ctx;
    if (!keep_input) ctx.consumable = &btf;  // as btfc compress: the input is not used again
    const double t = now_s();
    auto model = spec->first->encode(btf, spec->second, ctx);
    if (!model.ok()) {
      std::fprintf(stderr, "%s\n", model.status().message().c_str());
      return 3;
    }
    const double enc = now_s() - t;
    std::printf("codec      %s: encode %.2f s, payload %.1f MB (ratio %.0f : 1 vs float32), peak RSS %.2f GB (%.2f x input)\n",
                model.value()->spec().c_str(), enc, double(model.value()->payload_bytes()) / 1e6,
                double(d.num_values()) * 4 / double(model.value()->payload_bytes()), peak_rss_gb(), peak_rss_gb() / input_gb);
    for (const auto& [k, v] : model.value()->stats().numbers) std::printf("  %s = %.6g\n", k.c_str(), v);
    std::printf("  kernels ran on %s\n", ocl::device_summary().c_str());
    return 0;
  };
  if (!load.empty() && !codec_spec.empty()) {
    // --codec on a --dump file: a BTF of the synth's shape (--width x --height texels, UBO2003
    // directions, RGB) whose values are read from FILE instead of synthesized (~2 s from the page
    // cache where synthesis takes 8-49 s). The file must hold exactly that many values.
    BtfDesc desc;
    desc.width = width, desc.height = height, desc.channels = 3;
    desc.lights = DirectionSet::ubo2003(), desc.views = DirectionSet::ubo2003();
    auto btf = Btf::create(desc);
    std::FILE* f = btf.ok() ? std::fopen(load.c_str(), "rb") : nullptr;
    if (!f) {
      std::fprintf(stderr, "%s: cannot open or no memory for %s\n", load.c_str(), desc.summary().c_str());
      return 2;
    }
    std::fseek(f, 0, SEEK_END);
    const size_t bytes = size_t(std::ftell(f));
    std::fseek(f, 0, SEEK_SET);
    if (bytes != btf->size() * 4 || std::fread(btf->data(), 4, btf->size(), f) != btf->size()) {
      std::fprintf(stderr, "%s: %zu bytes, %s needs %zu\n", load.c_str(), bytes, desc.summary().c_str(), btf->size() * 4);
      return 2;
    }
    std::fclose(f);
    std::printf("input: %s (%s), %.2f GB float32\n", load.c_str(), desc.summary().c_str(), double(btf->size()) * 4 / 1e9);
    return run_codec(btf.value());
  }
  if (!load.empty()) {
    // A --dump file: m x n column-major float32, read into one buffer (the input of the peak RSS
    // ratio), of the kind a Btf holds (FloatBuffer: 2 MiB-aligned, huge pages requested), so the
    // passes see the TLB behaviour of the codec's own input.
    std::FILE* f = std::fopen(load.c_str(), "rb");
    if (!f) return 2;
    std::fseek(f, 0, SEEK_END);
    const size_t bytes = size_t(std::ftell(f));
    std::fseek(f, 0, SEEK_SET);
    const size_t m = load_rows, n = std::min(bytes / 4 / m, load_texels ? load_texels : bytes);
    FloatBuffer B(m * n);
    if (std::fread(B.data(), 4, B.size(), f) != B.size()) return 2;
    std::fclose(f);
    const double input_gb = double(B.size()) * 4 / 1e9;
    std::printf("input: %s, %zu x %zu float32, %.2f GB\n", load.c_str(), m, n, input_gb);
    if (streamed >= 0) {
      run_streamed(B.data(), m, n, input_gb);
      return 0;
    }
    run_svd(B.data(), m, n, input_gb, power, over, "fmf");
    return 0;
  }
  SynthOptions so;
  so.width = width, so.height = height, so.seed = 1;
  double t0 = now_s();
  auto btf = synthesize_btf(so);
  if (!btf.ok()) {
    std::fprintf(stderr, "%s\n", btf.status().message().c_str());
    return 2;
  }
  const double synth_s = now_s() - t0;
  const BtfDesc& d = btf->desc();
  const double input_gb = double(d.num_values()) * 4 / 1e9;
  const double rss_after_input = peak_rss_gb();
  std::printf("input: %s = %.3f G values, %.2f GB float32; synth %.1f s; peak RSS after synth %.2f GB\n", d.summary().c_str(),
              double(d.num_values()) / 1e9, input_gb, synth_s, rss_after_input);
  if (!dump.empty()) {
    std::FILE* f = std::fopen(dump.c_str(), "wb");
    if (!f || std::fwrite(btf->data(), 4, btf->size(), f) != btf->size()) return 2;
    std::fclose(f);
    std::printf("dumped %zu x %zu float32 matrix (column-major: rows = ABRDF, columns = texels) to %s\n", d.abrdf_size(),
                d.num_texels(), dump.c_str());
    if (dump_only && dump_dfmf.empty()) return 0;
  }
  if (!dump_dfmf.empty()) {
    // The matrices the dfmf encode factorizes (fmf.cpp): the automatic offset, then each channel
    // through dfmf_channel, texel by texel (num_images rows x texels, column-major).
    const size_t rows = d.num_images(), n = d.num_texels();
    const float offset = float(dfmf_auto_offset(*btf));
    std::vector<float> col(rows);
    for (int k = 0; k < 3; ++k) {
      const std::string path = dump_dfmf + "." + "yuv"[k] + ".f32";
      std::FILE* f = std::fopen(path.c_str(), "wb");
      if (!f) return 2;
      for (size_t t = 0; t < n; ++t) {
        dfmf_channel(btf->abrdf(t), rows, k, offset, col.data());
        if (std::fwrite(col.data(), 4, rows, f) != rows) return 2;
      }
      std::fclose(f);
      std::printf("dumped %zu x %zu float32 dfmf channel %c (offset %.9g) to %s\n", rows, n, "yuv"[k], offset, path.c_str());
    }
    if (dump_only) return 0;
  }

  if (!codec_spec.empty()) return run_codec(btf.value());
  auto run = [&](int q, int p, const char* label) { return run_svd(btf->data(), d.abrdf_size(), d.num_texels(), input_gb, q, p, label); };
  const double err = run(power, over, "fmf");
  if (svd_only) return 0;
  // The codec end to end (adds the half quantization and the model build).
  auto spec = resolve_spec("fmf:rank=" + std::to_string(rank) + ":power_iters=" + std::to_string(power) + ":oversample=" + std::to_string(over));
  Context ctx;
  t0 = now_s();
  auto model = spec->first->encode(btf.value(), spec->second, ctx);
  std::printf("codec      %s: encode %.2f s, payload %.1f MB (ratio %.0f : 1 vs float32), peak RSS %.2f GB (%.2f x input)\n",
              model.value()->spec().c_str(), now_s() - t0, double(model.value()->payload_bytes()) / 1e6,
              double(d.num_values()) * 4 / double(model.value()->payload_bytes()), peak_rss_gb(), peak_rss_gb() / input_gb);
  if (reference) {
    const double ref = run(12, 96, "reference");
    std::printf("error relative to the converged reference: %.4f (goal <= 1.01)\n", err / ref);
  }
  return 0;
}
