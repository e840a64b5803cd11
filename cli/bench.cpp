// `btfc bench` and `btfc render`: call codecs/measure.h and codecs/render.h, print tables, write
// CSV / JSON / PNG. No algorithms live here.
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>

#include "cli/commands.h"
#include "cli/outputs.h"
#include "formats/exr/envmap.h"
#include "codecs/measure.h"
#include "core/sysinfo.h"
#include "formats/btf_io.h"
#include "formats/reader.h"
#include "formats/preview.h"
#include "codecs/preview_panel.h"

namespace btfc::cli {
namespace {

using nlohmann::json;

json num(double v) { return std::isfinite(v) ? json(v) : json(nullptr); }

const char* k_csv_columns =
    "data,spec_given,spec,payload_bytes,ratio,bits_per_value,rmse,rel_l2,psnr,mean_ssim,render_ssim,encode_s,decode_s,"
    "evals_per_s,peak_rss_mb,tensor_digest,device,btfc_version,machine,command,file_bytes";

std::string csv_field(const std::string& s) {
  if (s.find_first_of(",\"\n") == std::string::npos) return s;
  std::string out = "\"";
  for (char c : s) out += c == '"' ? std::string("\"\"") : std::string(1, c);
  return out + "\"";
}

std::string csv_num(double v) {
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.9g", v);
  return buf;
}

std::string safe_name(std::string s) {
  for (char& c : s)
    if (!std::isalnum(static_cast<unsigned char>(c)) && c != '-' && c != '.' && c != '_' && c != '=') c = '_';
  return s;
}

double psnr_of(const BenchResult& r) { return r.metrics.psnr; }
double ssim_of(const BenchResult& r) { return r.metrics.mean_ssim; }

}  // namespace

int cmd_bench(const Global& g, const BenchArgs& a) {
  if (Status s = require_input(a.in); !s.ok()) return fail(g, s);
  if (a.csv == "-" && a.json_out == "-") return fail(g, invalid_argument("--csv - and --json-out -: only one of them can go to stdout"));
  if (!a.csv.empty() && !a.append)
    if (Status c = claim_output(a.csv, {a.in}, {"--csv", {".csv", ".txt"}, false, true}); !c.ok()) return fail(g, c);
  if (!a.json_out.empty())
    if (Status c = claim_output(a.json_out, {a.in}, {"--json-out", {".json"}, false, true}); !c.ok()) return fail(g, c);
  // Probed and opened once (formats/reader.h): streamed when larger than --max-memory, else read.
  auto input = open_input(a.in);
  if (!input.ok()) return fail(g, input.status());
  if (int code = 0; bench_streamed(g, a, *input.value(), code)) return code;  // streamed fmf
  std::vector<std::string> specs;
  for (const std::string& s : a.specs) {
    auto expanded = expand_sweep(s);
    if (!expanded.ok()) return fail(g, expanded.status());
    for (const std::string& e : expanded.value()) {
      auto ok = resolve_spec(e);  // every spec valid before the first (long) run
      if (!ok.ok()) return fail(g, ok.status());
      specs.push_back(e);
    }
  }
  // With a stream on stdout (--csv - / --json-out -) the table goes to stderr.
  const bool streaming = a.csv == "-" || a.json_out == "-";
  if (streaming && g.json) return fail(g, invalid_argument("--json and --csv - / --json-out -: only one report can go to stdout"));
  FILE* tbl = streaming ? stderr : stdout;
  auto btf = input.value()->read();
  if (!btf.ok()) return fail(g, btf.status());
  const std::string label = a.label.empty() ? std::filesystem::path(a.in).filename().string() : a.label;
  const std::string machine = machine_summary();
  std::vector<RgbImage> refs;
  if (!a.no_renders) {
    auto r = reference_renders(btf.value());
    if (!r.ok()) return fail(g, r.status().with_context(a.in));
    refs = std::move(r).value();
  }
  if (!a.renders_dir.empty()) {
    std::error_code ec;
    std::filesystem::create_directories(a.renders_dir, ec);
    if (ec) return fail(g, io_error(a.renders_dir + ": cannot create: " + ec.message()));
  }
  // Columns as wide as the longest label / spec, so long names do not shift the table.
  int lw = std::max<int>(16, int(label.size())), sw = 34;
  for (const std::string& sp : specs) sw = std::max(sw, int(sp.size()));
  if (!g.json && a.header)
    std::fprintf(tbl, "%-*s %-*s %8s %7s %10s %8s %7s %7s %8s %8s %9s %8s\n", lw, "data", sw, "codec", "ratio", "bpv", "RMSE", "PSNR", "SSIM",
                "rSSIM", "enc s", "dec s", "Meval/s", "peak MB");
  std::vector<BenchResult> runs;
  json rows = json::array();
  Progress progress(g.quiet || g.json);
  for (size_t i = 0; i < specs.size(); ++i) {
    BenchOptions opt;
    opt.seed = a.seed;
    opt.renders = !a.no_renders;
    opt.references = a.no_renders ? nullptr : &refs;
    opt.throughput_queries = a.throughput_queries;
    opt.progress = &progress;
    if (!g.quiet && !g.json && specs.size() > 1 && isatty(STDERR_FILENO))
      std::fprintf(stderr, "run %zu of %zu: %s\n", i + 1, specs.size(), specs[i].c_str());
    auto r = run_benchmark(btf.value(), specs[i], opt);
    if (!r.ok()) return fail(g, r.status().with_context(a.in + " with " + specs[i]));
    BenchResult& b = r.value();
    const double peak_mb = double(b.peak_rss_bytes) / (1 << 20);
    rows.push_back({{"data", label}, {"spec_given", b.spec_given}, {"spec", b.spec}, {"payload_bytes", b.payload_bytes},
                    {"file_bytes", b.file_bytes}, {"ratio", b.ratio}, {"bits_per_value", b.bits_per_value}, {"rmse", b.metrics.rmse},
                    {"rel_l2", num(b.metrics.rel_l2)}, {"psnr", num(b.metrics.psnr)}, {"psnr_peak", b.metrics.peak},
                    {"mean_ssim", b.metrics.mean_ssim}, {"render_ssim", a.no_renders ? json(nullptr) : json(b.render_ssim)},
                    {"encode_seconds", b.encode_seconds}, {"decode_seconds", b.decode_seconds},
                    {"evals_per_second", b.evals_per_second}, {"peak_rss_mb", peak_mb}, {"tensor_digest", b.tensor_digest},
                    {"device", b.device}});
    if (!g.json) {
      char rssim[16] = "n/a";  // --no-renders: not measured (not "nan")
      if (!a.no_renders) std::snprintf(rssim, sizeof rssim, "%.4f", b.render_ssim);
      std::fprintf(tbl, "%-*s %-*s %8.2f %7.4f %10.4g %8.3f %7.4f %7s %8.3f %8.3f %9.3f %8.0f\n", lw, label.c_str(), sw, specs[i].c_str(),
                   b.ratio, b.bits_per_value, b.metrics.rmse, b.metrics.psnr, b.metrics.mean_ssim, rssim, b.encode_seconds,
                   b.decode_seconds, b.evals_per_second / 1e6, peak_mb);
    }
    if (!a.renders_dir.empty())
      for (size_t k = 0; k < b.renders.size(); ++k) {
        const std::string path = a.renders_dir + "/" + safe_name(label + "-" + std::to_string(i) + "-" + specs[i]) +
                                 (k == 0 ? "-flat.png" : "-sphere.png");
        // Labelled: which run, which tile is which, and what the error colours mean.
        // The spec as given (the canonical one lists every default and is cut off at the panel's width).
        char numbers[96];
        std::snprintf(numbers, sizeof numbers, "PSNR %.2f dB  render SSIM %.4f  ratio %.1f", b.metrics.psnr, b.render_ssim, b.ratio);
        auto panel = preview_panel(refs[k], b.renders[k], 5.0, label + "  " + b.spec_given + (k == 0 ? "  flat" : "  sphere") + "\n" + numbers);
        if (!panel.ok()) return fail(g, panel.status().with_context(path));
        Status s = write_rgb_image(path, panel->image);
        if (!s.ok()) return fail(g, s);
      }
    b.model.reset();  // models can be large; the numbers are kept
    b.renders.clear();
    runs.push_back(std::move(b));
  }

  json pareto = json::array();
  if (a.pareto) {
    std::vector<const BenchResult*> ptrs;
    for (const BenchResult& r : runs) ptrs.push_back(&r);
    for (auto [name, fn] : {std::pair{"psnr", &psnr_of}, std::pair{"mean_ssim", &ssim_of}}) {
      const std::vector<size_t> front = pareto_front(ptrs, fn);
      if (!g.json) std::fprintf(tbl, "\nPareto front by %s (the best codec within each byte budget):\n  %-14s %-34s %10s\n", name, "budget bytes", "winner", name);
      for (size_t i : front) {
        pareto.push_back({{"metric", name}, {"budget_bytes", runs[i].payload_bytes}, {"spec", runs[i].spec_given}, {"value", num(fn(runs[i]))}});
        if (!g.json) std::fprintf(tbl, "  <= %-11llu %-34s %10.4f\n", (unsigned long long)runs[i].payload_bytes, runs[i].spec_given.c_str(), fn(runs[i]));
      }
    }
  }
  json report{{"btfc_version", BTFC_VERSION}, {"machine", machine}, {"command", g.command_line}, {"data", label},
              {"input", a.in}, {"shape", btf->desc().summary()}, {"runs", rows}};
  if (a.pareto) report["pareto"] = pareto;
  if (!a.json_out.empty()) {
    std::ofstream file;
    if (a.json_out != "-") file.open(a.json_out);
    std::ostream& f = a.json_out == "-" ? std::cout : file;
    f << report.dump(2) << "\n";
    if (!f) return fail(g, io_error(a.json_out + ": cannot write"));
  }
  if (!a.csv.empty()) {
    const bool to_stdout = a.csv == "-";
    const bool fresh = to_stdout || !a.append || !std::filesystem::exists(a.csv) || std::filesystem::file_size(a.csv) == 0;
    std::ofstream file;
    if (!to_stdout) file.open(a.csv, a.append ? std::ios::app : std::ios::trunc);
    std::ostream& f = to_stdout ? std::cout : file;
    if (fresh) f << k_csv_columns << "\n";
    for (const json& r : rows) {
      f << csv_field(label) << ',' << csv_field(r["spec_given"]) << ',' << csv_field(r["spec"]) << ','
        << r["payload_bytes"].get<uint64_t>() << ',' << csv_num(r["ratio"]) << ',' << csv_num(r["bits_per_value"]) << ','
        << csv_num(r["rmse"]) << ',' << (r["rel_l2"].is_null() ? "" : csv_num(r["rel_l2"])) << ','
        << (r["psnr"].is_null() ? "inf" : csv_num(r["psnr"])) << ',' << csv_num(r["mean_ssim"]) << ','
        << (r["render_ssim"].is_null() ? "" : csv_num(r["render_ssim"])) << ',' << csv_num(r["encode_seconds"]) << ','
        << csv_num(r["decode_seconds"]) << ',' << csv_num(r["evals_per_second"]) << ',' << csv_num(r["peak_rss_mb"]) << ','
        << r["tensor_digest"].get<uint32_t>() << ',' << csv_field(r["device"]) << ',' << BTFC_VERSION << ','
        << csv_field(machine) << ',' << csv_field(g.command_line) << ',' << r["file_bytes"].get<uint64_t>() << "\n";
    }
    if (!f) return fail(g, io_error(a.csv + ": cannot write"));
  }
  if (g.json) std::cout << report.dump(2) << "\n";
  else if (!g.quiet) std::fprintf(tbl, "machine: %s; kernels ran on %s\n", machine.c_str(), runs.empty() ? "-" : runs[0].device.c_str());
  return 0;
}

int cmd_render(const Global& g, const RenderArgs& a) {
  if (Status s = require_input(a.in); !s.ok()) return fail(g, s);
  if (Status c = claim_output(a.out, {a.in, a.env}, {"-o", {".png", ".exr"}}); !c.ok()) return fail(g, c);
  RenderSettings s;
  if (a.shape != "flat" && a.shape != "sphere") return fail(g, invalid_argument("--shape: expected flat or sphere, got '" + a.shape + "'"));
  s.shape = a.shape == "flat" ? RenderSettings::Shape::flat : RenderSettings::Shape::sphere;
  auto view = parse_theta_phi(a.view, "--view");
  if (!view.ok()) return fail(g, view.status());
  auto light = parse_theta_phi(a.light, "--light");
  if (!light.ok()) return fail(g, light.status());
  s.view = view.value(), s.light = light.value();
  s.intensity = a.intensity, s.size = a.size, s.tiles = a.tiles;
  if (a.distance > 0) s.light_kind = RenderSettings::LightKind::point, s.distance = a.distance;
  if (!a.env.empty()) {
    s.light_kind = RenderSettings::LightKind::environment;
    auto env = read_rgb_exr(a.env, s.environment.width, s.environment.height);
    if (!env.ok()) return fail(g, env.status().with_context(a.env));
    s.environment.rgb = std::move(env).value();
  }
  // A model renders through its own evaluation; anything else (image set, raw container, Bonn
  // file) as data interpolated between measured directions.
  Result<RgbImage> img = invalid_argument("render: nothing rendered");
  auto input = open_input(a.in);  // probed and opened once
  if (!input.ok()) return fail(g, input.status());
  if (const Model* model = input.value()->model()) {
    img = render(model->desc(), model_evaluator(*model), s);
  } else {
    auto btf = input.value()->read();
    if (!btf.ok()) return fail(g, btf.status());
    img = render(btf->desc(), btf_evaluator(btf.value()), s);
  }
  if (!img.ok()) return fail(g, img.status().with_context(a.in));
  tone_map(img.value(), a.exposure, a.tonemap == "reinhard" ? ToneMap::reinhard : ToneMap::none);
  Status st = std::filesystem::path(a.out).extension() == ".exr" ? write_rgb_exr(a.out, img->width, img->height, img->rgb)
                                                                   : write_rgb_image(a.out, img.value());
  if (!st.ok()) return fail(g, st);
  if (g.json) std::cout << json{{"output", a.out}, {"width", img->width}, {"height", img->height}}.dump(2) << "\n";
  else if (!g.quiet) std::printf("rendered %s -> %s (%dx%d)\n", a.in.c_str(), a.out.c_str(), img->width, img->height);
  return 0;
}

}  // namespace btfc::cli
