// Measuring codecs on a BTF: what `btfc bench` reports, so users can trade speed for accuracy on
// their own data rather than guess.
//
// One run = encode with a spec string, decode everything, compare, render, time random
// evaluations. Reported per run: payload bytes, the .btfc file's bytes, ratio (float32 input bytes / payload bytes) and
// bits per value, RMSE, relative L2, PSNR and mean SSIM over the BTF's images (core/metrics.h),
// mean SSIM over rendered images (codecs/render.h: the standard scenes below), encode and decode
// wall time, interpolated random evaluations per second (Model::eval_batch), the process's peak
// resident memory during the run (core/sysinfo.h: the input BTF, already resident, included) and
// the device the kernels ran on. `tensor_digest` is a CRC-32 of the model's tensors: the same spec
// on the same data gives the same digest and the same metrics (determinism).
//
// Sweeps: "fmf:rank=4,8,16" expands to one spec per value (several swept keys: their product, in
// the order given). Parameter values never contain commas, so a comma always means a sweep.
#pragma once
#include <memory>
#include <string>
#include <vector>

#include "codecs/codec.h"
#include "codecs/render.h"
#include "core/metrics.h"

namespace btfc {

Result<std::vector<std::string>> expand_sweep(const std::string& spec);

struct BenchOptions {
  uint64_t seed = 1;
  size_t throughput_queries = size_t(1) << 17;  // random interpolated evaluations per timing round
  double throughput_seconds = 0.3;              // timing rounds repeat until this much time passed
  bool renders = true;                          // rendered-image SSIM
  // reference_renders(btf) when the caller has them (several runs on the same data); else
  // run_benchmark renders the original itself.
  const std::vector<RgbImage>* references = nullptr;
  Progress* progress = nullptr;
};

struct BenchResult {
  std::string spec_given, spec;  // as given, and canonical (every key)
  uint64_t payload_bytes = 0;
  uint64_t file_bytes = 0;  // the .btfc save_model writes: payload + container framing + statistics
  double ratio = 0, bits_per_value = 0;
  Metrics metrics;
  double render_ssim = 0;  // mean over standard_renders()
  double encode_seconds = 0, decode_seconds = 0;
  double evals_per_second = 0;
  uint64_t peak_rss_bytes = 0;
  uint32_t tensor_digest = 0;
  std::string device;
  std::unique_ptr<Model> model;
  std::vector<RgbImage> renders;  // the model's standard_renders(), for previews
};

// The fixed scenes rendered for the rendered-image SSIM: the flat sample under a point light at
// theta 45 deg seen from the first measured view, and a sphere (96 px) under a directional light
// at theta 30 deg seen from +z.
std::vector<RenderSettings> standard_renders(const BtfDesc& desc);

// The original data rendered in the standard scenes.
Result<std::vector<RgbImage>> reference_renders(const Btf& btf);

Result<BenchResult> run_benchmark(const Btf& btf, const std::string& spec, const BenchOptions& opt);

// Indices of the runs on the rate-distortion Pareto front (no other run has fewer or equal bytes
// and a strictly higher `quality`, or fewer bytes and an equal one), sorted by bytes. `quality`
// picks the metric (e.g. PSNR or mean SSIM).
std::vector<size_t> pareto_front(const std::vector<const BenchResult*>& runs, double (*quality)(const BenchResult&));

// Model payload digest (ContainerWriter::tensor_digest of what save_model would write).
uint32_t model_digest(const Model& model);

}  // namespace btfc
