// Bounded-memory (out-of-core) variants of compress / decompress / bench. The algorithms live
// in formats/out_of_core.h and formats/btf_stream.h; this file decides when to use them and prints.
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <iostream>
#include <nlohmann/json.hpp>

#include "cli/commands.h"
#include "cli/outputs.h"
#include "codecs/codec.h"
#include "core/limits.h"
#include "core/memory.h"
#include "formats/bonn/bdi_work.h"
#include "formats/btf_io.h"
#include "formats/btf_stream.h"
#include "formats/image_set.h"
#include "formats/out_of_core.h"

namespace btfc::cli {
namespace {

using nlohmann::json;
using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }
json num(double v) { return std::isfinite(v) ? json(v) : json(nullptr); }
bool ends_with(const std::string& s, const std::string& x) { return s.size() >= x.size() && s.compare(s.size() - x.size(), x.size(), x) == 0; }

// The --max-memory limit (default: most of the free RAM). A limit the user gave also becomes the
// process-wide one (core/limits.h), so in-core decodes and model loads are held to it too.
Result<size_t> limit_of(const std::string& text) {
  if (text.empty()) return default_max_memory();
  BTFC_ASSIGN_OR_RETURN(size_t bytes, parse_size(text));
  set_memory_limit(bytes);
  return bytes;
}

// The streamed encode of `in` within `limit` (formats/out_of_core.h); fills `report` with what
// it did. `out` keeps an automatic working file alive until the caller is done with it.
Result<std::unique_ptr<Model>> encode_streamed(const Global& g, const std::string& in, const std::string& spec, const std::string& work_file,
                                               const std::string& temp_dir, size_t limit, unsigned long long seed, json& report,
                                               OutOfCoreResult& out, BtfInput* opened = nullptr) {
  Progress progress(g.quiet || g.json);
  OutOfCoreJob job;
  job.input = in, job.spec = spec, job.max_bytes = limit, job.seed = seed, job.work_file = work_file, job.temp_dir = temp_dir;
  job.progress = &progress;
  job.notes = !g.quiet && !g.json;
  job.opened = opened;
  Collective single;
  BTFC_ASSIGN_OR_RETURN(out, compress_out_of_core(job, single));
  const WorkFile& wf = out.work;
  report = json{{"max_memory", limit},
                {"work_file", wf.path},
                {"work_file_built", wf.built},
                {"work_file_reused", wf.reused},
                {"work_file_seconds", wf.seconds},
                {"work_file_bytes", wf.bytes_written},
                {"work_file_scale", wf.scale},
                {"work_file_note", wf.note},
                {"chunks", out.chunks},
                {"chunk_texels", out.chunk_texels},
                {"passes", out.stats.passes},
                {"bytes_read", out.stats.bytes_read},
                {"pass_seconds", out.stats.pass_seconds},
                {"factorize_seconds", out.factorize_seconds},
                {"buffer_bytes", out.stats.buffer_bytes}};
  return std::move(out.model);
}

void print_report(const json& r) {
  const bool in_place = r["work_file_note"].get<std::string>().find("in place") != std::string::npos;
  std::cout << "  out of core: " << (in_place ? "raw .btfc streamed in place (no working file) " : "working file ")
            << r["work_file"].get<std::string>()
            << (in_place ? "" : r["work_file_built"].get<bool>() ? " (built in " + std::to_string(r["work_file_seconds"].get<double>()) + " s)" : r["work_file_reused"].get<bool>() ? " (reused)" : " (the input)")
            << ", " << r["chunks"] << " chunks of " << r["chunk_texels"] << " texels\n"
            << "  " << r["passes"] << " passes, " << format_bytes(r["bytes_read"].get<uint64_t>()) << " read, factorization "
            << r["factorize_seconds"].get<double>() << " s, peak RSS " << format_bytes(r["peak_rss_bytes"].get<uint64_t>())
            << " (limit " << format_bytes(r["max_memory"].get<uint64_t>()) << " + 200 MiB fixed overhead)\n";
}

}  // namespace

bool compress_streamed(const Global& g, const CompressArgs& a, BtfInput& input, int& code) {
  auto limit = limit_of(a.max_memory);
  if (!limit.ok()) return code = fail(g, limit.status()), true;
  const BtfDesc* desc = &input.desc();
  if (desc->num_values() * 4 <= *limit && a.work_file.empty()) return false;
  const auto t0 = Clock::now();
  json report;
  OutOfCoreResult ooc;
  std::error_code ec;
  const std::filesystem::path parent = std::filesystem::absolute(a.out, ec).parent_path();
  if (auto r = resolve_spec(a.spec); r.ok() && !r->first->streaming())
    return code = fail(g, invalid_argument(a.in + ": the BTF (" + format_bytes(desc->num_values() * 4) + " as float32) does not fit in --max-memory " +
                                           format_bytes(*limit) + "; " + r->first->name() + " needs it in memory (" + only_streaming_codecs() + ")")),
           true;
  auto model = encode_streamed(g, a.in, a.spec, a.work_file, parent.string(), *limit, a.seed, report, ooc, &input);
  if (!model.ok()) return code = fail(g, model.status()), true;
  const double enc_s = since(t0);
  note_clamped(g, a.in, model.value()->stats());
  Status s = write_model(*model.value(), a.out);
  if (!s.ok()) return code = fail(g, s), true;
  report["peak_rss_bytes"] = peak_rss_bytes();
  const double ratio = double(desc->num_values()) * 4.0 / double(std::filesystem::file_size(a.out));
  if (g.json) {
    json j{{"input", a.in}, {"output", a.out}, {"spec", model.value()->spec()}, {"encode_seconds", enc_s},
           {"file_bytes", std::filesystem::file_size(a.out)}, {"ratio_vs_float32", ratio}, {"out_of_core", report}};
    json st;
    for (const auto& [k, v] : model.value()->stats().numbers)
      if (k != "encode_seconds") st[k] = num(v);  // one encode time per run: the one above
    for (const auto& [k, v] : model.value()->stats().notes) st[k] = v;
    j["stats"] = st;
    std::cout << j.dump(2) << "\n";
  } else if (!g.quiet) {
    std::cout << "compressed " << a.in << " (" << desc->summary() << ") out of core with " << model.value()->spec() << "\n"
              << "  -> " << a.out << ", ratio " << ratio << " : 1 vs float32, encode " << enc_s << " s\n";
    print_report(report);
  }
  code = 0;
  return true;
}

bool decompress_streamed(const Global& g, const DecompressArgs& a, int& code) {
  auto limit = limit_of(a.max_memory);
  if (!limit.ok()) return code = fail(g, limit.status()), true;
  const bool subset = !a.region.empty() || !a.lights.empty() || !a.views.empty() || a.lod != 0;
  if (!ends_with(a.out, ".btf")) {
    if (subset) return false;
    auto model = open_model(a.in);
    if (!model.ok()) return false;
    const uint64_t need = model.value()->desc().num_values() * 4;
    if (need <= *limit) return false;
    // A raw .btfc written band by band as the model decodes, or an image set view by view
    // (groups of lights).
    const bool raw = ends_with(a.out, ".btfc");
    const Model& m = *model.value();
    const auto t0 = Clock::now();
    Status s = raw ? decode_to_raw_btfc(m, a.out, *limit)
                   : write_image_set_streamed(m.desc(), a.out, a.format == "png" ? ImageFormat::png : ImageFormat::exr, *limit,
                                              [&](size_t v, size_t l0, size_t n, Btf& part) {
                                                DecodeRequest req;
                                                req.views = {int(v)};
                                                for (size_t l = l0; l < l0 + n; ++l) req.lights.push_back(int(l));
                                                return m.decode(req, part);
                                              });
    if (!s.ok()) return code = fail(g, s.with_context(a.in)), true;
    const double dec_s = since(t0);
    const char* what = raw ? "raw .btfc" : "image set";
    if (g.json)
      std::cout << json{{"output", a.out}, {"desc", m.desc().summary()}, {"decode_seconds", dec_s}, {"format", what},
                        {"max_memory", *limit}, {"peak_rss_bytes", peak_rss_bytes()}}.dump(2) << "\n";
    else if (!g.quiet)
      std::cout << "decoded " << a.in << " -> " << a.out << " (" << what << ", in parts within --max-memory): " << m.desc().summary()
                << " in " << dec_s << " s, peak RSS " << format_bytes(peak_rss_bytes()) << "\n";
    code = 0;
    return true;
  }
  if (subset) return code = fail(g, invalid_argument("decompress -o OUT.btf (Bonn BDI) writes the whole BTF; --region/--lights/--views/--lod need .btfc or an image set")), true;
  auto model = open_model(a.in);
  if (!model.ok()) return code = fail(g, model.status()), true;
  const auto t0 = Clock::now();
  Status s = decode_to_bdi(*model.value(), a.out, *limit);
  if (!s.ok()) return code = fail(g, s.with_context(a.in)), true;
  const double dec_s = since(t0);
  if (g.json)
    std::cout << json{{"output", a.out}, {"desc", model.value()->desc().summary()}, {"decode_seconds", dec_s}, {"format", "Bonn BDI"},
                      {"max_memory", *limit}, {"peak_rss_bytes", peak_rss_bytes()}}.dump(2) << "\n";
  else if (!g.quiet)
    std::cout << "decoded " << a.in << " -> " << a.out << " (Bonn BDI): " << model.value()->desc().summary() << " in " << dec_s << " s, peak RSS "
              << format_bytes(peak_rss_bytes()) << "\n";
  code = 0;
  return true;
}

bool bench_streamed(const Global& g, const BenchArgs& a, BtfInput& input, int& code) {
  auto limit = limit_of(a.max_memory);
  if (!limit.ok()) return code = fail(g, limit.status()), true;
  const BtfDesc* desc = &input.desc();
  if (desc->num_values() * 4 <= *limit) return false;
  const std::string label = a.label.empty() ? a.in : a.label;
  json rows = json::array();
  if (!g.json && a.header)
    std::printf("%-18s %-30s %9s %10s %9s %8s %9s %9s\n", "data", "codec (as given)", "ratio", "RMSE", "PSNR", "SSIM", "enc s", "dec s");
  std::error_code ec;
  const std::string temp_dir = std::filesystem::temp_directory_path(ec).string();
  register_work_dir(temp_dir);  // SIGINT / SIGTERM remove the working file there too
  for (const std::string& spec : a.specs) {
    json report;
    OutOfCoreResult ooc;
    const auto t0 = Clock::now();
    auto model = encode_streamed(g, a.in, spec, "", temp_dir, *limit, a.seed, report, ooc, &input);
    if (!model.ok()) return code = fail(g, model.status().with_context(a.in)), true;
    const double enc_s = since(t0);
    // The reference is what the factorization read: the raw .btfc in place, or the working file.
    const std::string ref = report["work_file"].get<std::string>();
    const auto t1 = Clock::now();
    Result<Metrics> m = invalid_argument(ref + ": no reference");
    if (ref == a.in && is_raw_btfc_file(a.in)) {
      auto src = open_raw_chunks(a.in, uint32_t(report["chunk_texels"].get<uint64_t>() / uint64_t(desc->width)));
      if (!src.ok()) return code = fail(g, src.status()), true;
      m = compare_streamed(*src.value(), *desc, a.in, *model.value());  // decodes chunk by chunk while comparing
    } else {
      auto file = BdiChunks::open(ref);
      if (!file.ok()) return code = fail(g, file.status()), true;
      m = compare_streamed(file.value(), *model.value());
    }
    if (!m.ok()) return code = fail(g, m.status()), true;
    const double dec_s = since(t1);
    const double ratio = double(desc->num_values()) * 4.0 / double(model.value()->payload_bytes());
    report["peak_rss_bytes"] = peak_rss_bytes();
    rows.push_back({{"data", label}, {"spec", model.value()->spec()}, {"spec_given", spec}, {"ratio", ratio},
                    {"payload_bytes", model.value()->payload_bytes()}, {"rmse", m->rmse}, {"rel_l2", num(m->rel_l2)},
                    {"psnr", num(m->psnr)}, {"mean_ssim", nullptr}, {"encode_seconds", enc_s}, {"decode_compare_seconds", dec_s},
                    {"out_of_core", report}});
    if (!g.json)
      std::printf("%-18s %-30s %9.2f %10.4g %9.3f %8s %9.3f %9.3f\n", label.c_str(), spec.c_str(), ratio, m->rmse, m->psnr, "n/a", enc_s, dec_s);
  }
  if (g.json) std::cout << rows.dump(2) << "\n";
  else std::printf("out of core (--max-memory %s): SSIM not computed (needs whole images); dec s includes the comparison\n", format_bytes(*limit).c_str());
  code = 0;
  return true;
}

}  // namespace btfc::cli
