#include "codecs/measure.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <random>

#include "core/cl_runtime.h"
#include "core/sysinfo.h"

namespace btfc {
namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

std::vector<std::string> split(const std::string& s, char sep) {
  std::vector<std::string> out;
  size_t start = 0;
  for (;;) {
    const size_t k = s.find(sep, start);
    out.push_back(s.substr(start, k == std::string::npos ? std::string::npos : k - start));
    if (k == std::string::npos) return out;
    start = k + 1;
  }
}

// Random queries at arbitrary directions (theta up to 80 deg): the interpolating path.
std::vector<EvalQuery> random_queries(const BtfDesc& d, size_t n, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<EvalQuery> q(n);
  const double max_theta = 80.0 * 3.14159265358979323846 / 180;
  for (EvalQuery& e : q) {
    e.x = int(u(rng) * d.width) % d.width, e.y = int(u(rng) * d.height) % d.height;
    e.wl = dir_from_theta_phi(u(rng) * max_theta, u(rng) * 2 * 3.14159265358979323846);
    e.wv = dir_from_theta_phi(u(rng) * max_theta, u(rng) * 2 * 3.14159265358979323846);
  }
  return q;
}

}  // namespace

Result<std::vector<std::string>> expand_sweep(const std::string& spec) {
  BTFC_ASSIGN_OR_RETURN(SpecString parsed, parse_spec_string(spec));
  std::vector<std::string> out{parsed.codec};
  for (const auto& [key, value] : parsed.values) {
    const std::vector<std::string> values = split(value, ',');
    for (const std::string& v : values)
      if (v.empty()) return invalid_argument("spec '" + spec + "': empty value in the sweep of '" + key + "'");
    std::vector<std::string> next;
    for (const std::string& prefix : out)
      for (const std::string& v : values) next.push_back(prefix + ":" + key + "=" + v);
    out = std::move(next);
    if (out.size() > 4096) return invalid_argument("spec '" + spec + "': the sweep expands to more than 4096 runs");
  }
  return out;
}

uint32_t model_digest(const Model& model) {
  ContainerWriter w;
  w.set_desc(model.desc());
  const std::string& spec = model.spec();
  const Codec* codec = find_codec(spec.substr(0, spec.find(':')));
  w.set_codec({codec ? codec->name() : spec, codec ? codec->payload_version() : 0, spec, ""});
  if (!model.save(w).ok()) return 0;
  return w.tensor_digest();
}

std::vector<RenderSettings> standard_renders(const BtfDesc& desc) {
  RenderSettings flat;
  flat.shape = RenderSettings::Shape::flat;
  flat.light_kind = RenderSettings::LightKind::point;
  flat.view = desc.views.dirs.empty() || desc.views.dirs[0].z <= 0 ? Vec3{0, 0, 1} : desc.views.dirs[0];
  flat.light = dir_from_theta_phi(45.0 * 3.14159265358979323846 / 180, 0.3);
  flat.distance = 2.0;
  RenderSettings sphere;
  sphere.shape = RenderSettings::Shape::sphere;
  sphere.light_kind = RenderSettings::LightKind::directional;
  sphere.view = {0, 0, 1};
  sphere.light = dir_from_theta_phi(30.0 * 3.14159265358979323846 / 180, 2.0);
  sphere.size = 96;
  return {flat, sphere};
}

Result<std::vector<RgbImage>> reference_renders(const Btf& btf) {
  std::vector<RgbImage> out;
  for (const RenderSettings& s : standard_renders(btf.desc())) {
    BTFC_ASSIGN_OR_RETURN(RgbImage img, render(btf.desc(), btf_evaluator(btf), s));
    out.push_back(std::move(img));
  }
  return out;
}

Result<BenchResult> run_benchmark(const Btf& btf, const std::string& spec, const BenchOptions& opt) {
  BTFC_ASSIGN_OR_RETURN(auto resolved, resolve_spec(spec));
  auto [codec, params] = std::move(resolved);
  BenchResult r;
  r.spec_given = spec;
  reset_peak_rss();
  Context ctx;
  ctx.seed = opt.seed;
  ctx.progress = opt.progress;
  auto t0 = Clock::now();
  BTFC_ASSIGN_OR_RETURN(r.model, codec->encode(btf, params, ctx));
  r.encode_seconds = since(t0);
  r.spec = r.model->spec();
  {
    Btf decoded;
    t0 = Clock::now();
    BTFC_RETURN_IF_ERROR(r.model->decode_all(decoded));
    r.decode_seconds = since(t0);
    BTFC_ASSIGN_OR_RETURN(r.metrics, compare_btf(btf, decoded, true));
  }
  r.payload_bytes = r.model->payload_bytes();
  BTFC_ASSIGN_OR_RETURN(r.file_bytes, model_file_bytes(*r.model, *codec));
  const double values = double(btf.desc().num_values());
  r.ratio = r.payload_bytes ? values * 4.0 / double(r.payload_bytes) : 0;
  r.bits_per_value = double(r.payload_bytes) * 8.0 / values;
  r.tensor_digest = model_digest(*r.model);

  if (opt.renders) {
    std::vector<RgbImage> own;
    if (!opt.references) {
      BTFC_ASSIGN_OR_RETURN(own, reference_renders(btf));
    }
    const std::vector<RgbImage>& refs = opt.references ? *opt.references : own;
    const std::vector<RenderSettings> scenes = standard_renders(btf.desc());
    if (refs.size() != scenes.size()) return invalid_argument("run_benchmark: reference renders do not match the standard scenes");
    double sum = 0;
    for (size_t k = 0; k < scenes.size(); ++k) {
      BTFC_ASSIGN_OR_RETURN(RgbImage got, render(btf.desc(), model_evaluator(*r.model), scenes[k]));
      sum += render_ssim(refs[k], got);
      r.renders.push_back(std::move(got));
    }
    r.render_ssim = sum / double(scenes.size());
  }

  if (opt.throughput_queries > 0) {
    const std::vector<EvalQuery> q = random_queries(btf.desc(), opt.throughput_queries, opt.seed);
    std::vector<float> out(q.size() * size_t(btf.desc().channels));
    BTFC_RETURN_IF_ERROR(r.model->eval_batch(q, out.data()));  // warm-up: kernel build, caches
    size_t done = 0;
    t0 = Clock::now();
    do {
      BTFC_RETURN_IF_ERROR(r.model->eval_batch(q, out.data()));
      done += q.size();
    } while (since(t0) < opt.throughput_seconds);
    r.evals_per_second = double(done) / since(t0);
  }
  r.peak_rss_bytes = peak_rss_bytes();
  r.device = ocl::device_summary();
  return r;
}

std::vector<size_t> pareto_front(const std::vector<const BenchResult*>& runs, double (*quality)(const BenchResult&)) {
  std::vector<size_t> idx(runs.size());
  for (size_t i = 0; i < idx.size(); ++i) idx[i] = i;
  // By bytes, then best quality first: a run is on the front when it beats every cheaper one.
  std::stable_sort(idx.begin(), idx.end(), [&](size_t a, size_t b) {
    if (runs[a]->payload_bytes != runs[b]->payload_bytes) return runs[a]->payload_bytes < runs[b]->payload_bytes;
    return quality(*runs[a]) > quality(*runs[b]);
  });
  std::vector<size_t> front;
  double best = -std::numeric_limits<double>::infinity();
  for (size_t i : idx) {
    const double q = quality(*runs[i]);
    if (q > best) front.push_back(i), best = q;
  }
  return front;
}

}  // namespace btfc
