// btfc subcommands: call the library, print tables or JSON. No algorithms live here.
#include "cli/commands.h"
#include "cli/outputs.h"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "codecs/codec.h"
#include "formats/exr/envmap.h"
#include "codecs/target.h"
#include "core/cl_runtime.h"
#include "core/container.h"
#include "core/metrics.h"
#include "core/synth.h"
#include "formats/bonn/bonn_btf.h"
#include "formats/btf_io.h"
#include "formats/reader.h"
#include "formats/preview.h"

namespace btfc::cli {

using nlohmann::json;
using Clock = std::chrono::steady_clock;

int exit_code(const Status& s) {
  switch (s.code()) {
    case StatusCode::ok: return 0;
    case StatusCode::invalid_argument: return 1;
    case StatusCode::io_error:
    case StatusCode::corrupt_data:
    case StatusCode::unsupported: return 2;
    case StatusCode::codec_error:
    case StatusCode::device_error: return 3;
  }
  return 3;
}

int fail(const Global& g, const Status& s) {
  const std::string msg = user_paths(s.message());  // never an internal temporary name
  if (g.json) std::cout << json{{"error", msg}, {"code", status_code_name(s.code())}}.dump(2) << "\n";
  std::cerr << "error: " << msg << "\n";
  return exit_code(s);
}

Result<Vec3> parse_theta_phi(const std::string& text, const char* what) {
  double th = 0, ph = 0;
  char extra = 0;
  if (std::sscanf(text.c_str(), "%lf,%lf%c", &th, &ph, &extra) != 2 || !std::isfinite(th) || !std::isfinite(ph) || th < 0 || th > 180)
    return invalid_argument(std::string(what) + ": expected THETA,PHI in degrees (theta in [0, 180]), got '" + text + "'");
  const double k = 3.14159265358979323846 / 180.0;
  return dir_from_theta_phi(th * k, ph * k);
}

namespace {

bool ends_with(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

double dot3(const Vec3& a, const Vec3& b) { return double(a.x) * b.x + double(a.y) * b.y + double(a.z) * b.z; }

double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

// A finite JSON number, or null (JSON has no infinity).
json num(double v) { return std::isfinite(v) ? json(v) : json(nullptr); }

Result<std::vector<int>> parse_ints(const std::string& text, const char* what) {
  std::vector<int> out;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ',')) {
    char* end = nullptr;
    long v = std::strtol(item.c_str(), &end, 10);
    if (item.empty() || *end != '\0') return invalid_argument(std::string(what) + ": '" + item + "' is not an integer");
    out.push_back(int(v));
  }
  return out;
}

Result<DirectionSet> parse_direction_set(const std::string& text, const char* what) {
  if (text == "ubo2003") return DirectionSet::ubo2003();
  if (text == "ubo2014") return DirectionSet::ubo2014();
  BTFC_ASSIGN_OR_RETURN(Vec3 d, parse_theta_phi(text, what));
  return DirectionSet::single(d);
}

// `skip`: a key the caller already reports (compress prints its own encode time: one per run).
void print_stats(const ModelStats& st, json* j, const char* skip = nullptr) {
  for (const auto& [k, v] : st.numbers) {
    if (skip && k == skip) continue;
    if (j) (*j)[k] = num(v);
    else std::cout << "  " << k << " = " << v << "\n";
  }
  for (const auto& [k, v] : st.notes) {
    if (j) (*j)[k] = v;
    else std::cout << "  " << k << " = " << v << "\n";
  }
}

}  // namespace

void note_clamped(const Global& g, const std::string& input, const ModelStats& stats) {
  if (g.quiet) return;
  for (const auto& [k, v] : stats.notes)
    if (k.rfind("clamped", 0) == 0 || k.find("_clamped") != std::string::npos) std::cerr << "note: " << input << ": " << v << "\n";
}

void set_device(const std::string& choice) {
  auto c = ocl::parse_device_choice(choice);
  // `auto` is the default: left to the process, so BTFC_FORCE_CPU=1 still forces the CPU path
  // (setting it explicitly here had made the suite's CPU pass run the CLI tests on OpenCL).
  if (c.ok() && c.value() != ocl::DeviceChoice::automatic) ocl::set_device_choice(c.value());
}

int cmd_devices(const Global& g) {
  auto devs = ocl::list_devices();
  if (!devs.ok()) {
    if (g.json) std::cout << json{{"devices", json::array()}, {"note", devs.status().message()}}.dump(2) << "\n";
    else std::cout << "no OpenCL device: " << devs.status().message() << "\nbtfc runs its C++ reference path.\n";
    return 0;
  }
  json j = json::array();
  for (size_t i = 0; i < devs->size(); ++i) {
    const ocl::DeviceInfo& d = (*devs)[i];
    j.push_back({{"index", i}, {"platform", d.platform}, {"name", d.name}, {"type", d.type}, {"version", d.version},
                 {"compute_units", d.compute_units}, {"global_mem", d.global_mem}, {"max_alloc", d.max_alloc}});
    if (!g.json)
      std::printf("%zu: %s [%s] %s, %s, %d compute units, %.2f GiB global, %.2f GiB max allocation\n", i, d.name.c_str(),
                  d.type.c_str(), d.platform.c_str(), d.version.c_str(), d.compute_units, double(d.global_mem) / (1 << 30),
                  double(d.max_alloc) / (1 << 30));
  }
  auto rt = ocl::Runtime::get();
  if (g.json) std::cout << json{{"devices", j}, {"selected", rt.ok() ? rt.value()->info().name : ""}}.dump(2) << "\n";
  else std::printf("selected: %s (BTFC_CL_DEVICE = index or name substring to change)\n", rt.ok() ? rt.value()->info().name.c_str() : rt.status().message().c_str());
  return 0;
}

int cmd_codecs(const Global& g, bool names_only) {
  json j = json::array();
  for (const Codec* c : all_codecs()) {
    if (names_only) {
      std::cout << c->name() << "\n";
      continue;
    }
    if (g.json) {
      json params = json::array();
      for (const ParamSpec& p : c->params()) {
        json jp{{"name", p.name}, {"default", p.default_value}, {"help", p.help}};
        if (p.type == ParamSpec::Type::choice) jp["choices"] = p.choices;
        else jp["type"] = p.type == ParamSpec::Type::integer ? "int" : "real", jp["min"] = p.min, jp["max"] = p.max;
        params.push_back(jp);
      }
      j.push_back({{"name", c->name()}, {"summary", c->summary()}, {"payload_version", c->payload_version()}, {"params", params}});
    } else {
      std::cout << c->name() << " - " << c->summary() << "\n" << describe_params(c->params());
    }
  }
  if (g.json && !names_only) std::cout << j.dump(2) << "\n";
  return 0;
}

int cmd_synth(const Global& g, const SynthArgs& a) {
  if (Status c = claim_output(a.out, {}, {"-o", {".btfc"}, true}); !c.ok()) return fail(g, c);
  SynthOptions o;
  o.width = a.width;
  o.height = a.height;
  o.seed = a.seed;
  o.bump = a.bump;
  o.scale = a.scale;
  o.noise = a.noise;
  auto lights = parse_direction_set(a.lights, "--lights");
  if (!lights.ok()) return fail(g, lights.status());
  auto views = parse_direction_set(a.views, "--views");
  if (!views.ok()) return fail(g, views.status());
  o.lights = lights.value();
  o.views = views.value();
  auto btf = synthesize_btf(o);
  if (!btf.ok()) return fail(g, btf.status());
  Status s = write_btf(btf.value(), a.out, a.format == "png" ? ImageFormat::png : ImageFormat::exr);
  if (!s.ok()) return fail(g, s);
  if (g.json) std::cout << json{{"output", a.out}, {"desc", btf->desc().summary()}}.dump(2) << "\n";
  else if (!g.quiet) std::cout << "wrote " << a.out << ": " << btf->desc().summary() << "\n";
  return 0;
}

static int info_bonn(const Global& g, const std::string& path) {
  BonnInfo info;
  auto model = open_bonn_model(path, &info);
  if (!model.ok()) return fail(g, model.status());
  const BtfDesc& d = info.desc;
  json j{{"path", path}, {"format", std::string("Bonn ") + bonn_kind_name(info.kind)}, {"signature", info.signature},
         {"desc", d.summary()}, {"width", d.width}, {"height", d.height}, {"channels", d.channels}, {"lights", d.num_lights()},
         {"views", d.num_views()}, {"file_bytes", info.file_size},
         {"ratio_vs_float32", double(d.num_values()) * 4.0 / double(info.file_size)}, {"ubo2014_dome1", info.dome1}};
  for (const auto& [k, v] : info.notes()) j[k] = v;
  if (g.json) {
    std::cout << j.dump(2) << "\n";
    return 0;
  }
  std::cout << path << ": Bonn " << bonn_kind_name(info.kind) << " (" << info.signature << "), " << info.file_size << " bytes\n"
            << "  " << d.summary() << "\n";
  for (const auto& [k, v] : info.notes()) std::cout << "  " << k << ": " << v << "\n";
  return 0;
}

int cmd_info(const Global& g, const std::string& path, bool verify) {
  if (Status s = require_input(path); !s.ok()) return fail(g, s);
  const BtfReader* reader = find_reader(path);
  const std::string kind = reader ? reader->name : "btfc";
  if (kind == "image-set") {
    auto in = open_input(path);  // planned, not read
    if (!in.ok()) return fail(g, in.status());
    const BtfDesc& d = in.value()->desc();
    if (g.json) std::cout << json{{"path", path}, {"kind", "image set"}, {"desc", d.summary()}, {"hdr", d.hdr}}.dump(2) << "\n";
    else std::cout << path << ": image set, " << d.summary() << (d.hdr ? ", HDR" : ", LDR (sRGB-decoded)") << "\n";
    return 0;
  }
  if (kind == "bonn") return info_bonn(g, path);
  auto rd = ContainerReader::open(path);
  if (!rd.ok()) return fail(g, rd.status());
  if (verify) {
    Status s = rd->verify_all();
    if (!s.ok()) return fail(g, s);
  }
  const BtfDesc& d = rd->desc();
  const uint64_t raw_bytes = uint64_t(d.num_values()) * 4;
  json j{{"path", path}, {"desc", d.summary()}, {"width", d.width}, {"height", d.height}, {"channels", d.channels},
         {"lights", d.num_lights()}, {"views", d.num_views()}, {"codec", rd->codec().name}, {"spec", rd->codec().spec},
         {"payload_version", rd->codec().payload_version}, {"written_by", rd->codec().btfc_version},
         {"file_bytes", rd->file_size()}, {"ratio_vs_float32", double(raw_bytes) / double(rd->file_size())}};
  if (verify) j["verified"] = true;
  json tensors = json::array();
  for (const TensorInfo& t : rd->tensors()) tensors.push_back({{"name", t.name}, {"dtype", dtype_name(t.dtype)}, {"shape", t.shape}, {"bytes", t.size}});
  j["tensors"] = tensors;
  if (rd->codec().name != "raw") {
    auto model = load_model(rd.value());
    if (!model.ok()) return fail(g, model.status());
    json st;
    print_stats(model.value()->stats(), &st);
    j["stats"] = st;
  }
  j["encode_stats"] = rd->stats();
  if (g.json) {
    std::cout << j.dump(2) << "\n";
    return 0;
  }
  std::cout << path << ": " << rd->codec().name << " (" << rd->codec().spec << "), payload v" << rd->codec().payload_version
            << ", written by btfc " << rd->codec().btfc_version << "\n"
            << "  " << d.summary() << (d.hdr ? ", HDR" : "") << "\n"
            << "  " << rd->file_size() << " bytes, ratio " << j["ratio_vs_float32"].get<double>() << " : 1 vs float32"
            << (verify ? ", all checksums verified" : "") << "\n";
  for (const TensorInfo& t : rd->tensors()) {
    std::cout << "  tensor " << t.name << " " << dtype_name(t.dtype) << " [";
    for (size_t i = 0; i < t.shape.size(); ++i) std::cout << (i ? " x " : "") << t.shape[i];
    std::cout << "] " << t.size << " bytes\n";
  }
  if (!rd->stats().empty()) {
    std::cout << "  encode statistics:\n";
    std::stringstream ss(rd->stats());
    for (std::string line; std::getline(ss, line);) std::cout << "    " << line << "\n";
  }
  return 0;
}

// The spec as the output's writer needs it (formats/btf_io.h spec_for_output: a Bonn DFMF file
// holds only colour model 11's fixed luminance offset).
static CompressArgs for_output(const CompressArgs& in, const Global& g) {
  CompressArgs a = in;
  std::string note;
  a.spec = spec_for_output(a.spec, a.out, &note);
  if (!note.empty() && !g.quiet) std::cerr << "note: " << a.out << ": " << note << "\n";
  return a;
}

int cmd_compress(const Global& g, const CompressArgs& given) {
  const CompressArgs a = for_output(given, g);
  if (Status s = require_input(a.in); !s.ok()) return fail(g, s);
  if (Status c = claim_output(a.out, {a.in, a.work_file}, {"-o", {".btfc", ".btf"}}); !c.ok()) return fail(g, c);
  // Probed and opened once (formats/reader.h): its shape decides in core or out of core.
  auto t0 = Clock::now();
  auto input = open_input(a.in);
  if (!input.ok()) return fail(g, input.status());
  if (int code = 0; compress_streamed(g, a, *input.value(), code)) return code;
  auto resolved = resolve_spec(a.spec);
  if (!resolved.ok()) return fail(g, resolved.status());
  auto [codec, params] = std::move(resolved).value();
  auto btf = input.value()->read();
  if (!btf.ok()) return fail(g, btf.status());
  const double read_s = seconds_since(t0);
  Progress progress(g.quiet || g.json);
  Context ctx;
  ctx.seed = a.seed;
  ctx.progress = &progress;
  t0 = Clock::now();
  json target_json;
  Result<std::unique_ptr<Model>> model = unsupported("compress: no model");
  if (a.target_psnr || a.target_ssim || a.max_bytes) {
    Target t;
    t.kind = a.target_psnr ? Target::Kind::psnr : a.target_ssim ? Target::Kind::ssim : Target::Kind::max_bytes;
    t.value = a.target_psnr ? *a.target_psnr : a.target_ssim ? *a.target_ssim : *a.max_bytes;
    auto choice = choose_for_target(btf.value(), a.spec, t, ctx);
    if (!choice.ok()) return fail(g, choice.status().with_context(a.in));
    TargetChoice& c = choice.value();
    target_json = {{"knob", c.knob}, {"value", c.knob_value}, {"reached", num(c.measure)}, {"probes", json::array()}};
    if (c.knob_limit > 0) target_json["knob_limit"] = c.knob_limit;
    if (!c.variants.empty()) target_json["variants"] = c.variants;
    for (const TargetProbe& p : c.probes)
      target_json["probes"].push_back({{"knob", p.knob}, {"measure", num(p.measure)}, {"meets", p.meets}});
    if (!g.json && !g.quiet) {
      std::cout << "target: chose " << c.knob << " = " << c.knob_value << " (reached " << c.measure << "); probes:";
      for (const TargetProbe& p : c.probes) std::cout << " " << p.knob << (p.meets ? "+" : "-") << "(" << p.measure << ")";
      std::cout << "\n";
      if (!c.variants.empty())
        std::cout << (t.kind == Target::Kind::max_bytes ? "target: best fit per setting:" : "target:") << c.variants << "\n";
      if (c.knob_limit > 0)
        std::cout << "target: " << c.knob << " limited to " << c.knob_limit << " for this data's size (the codec's budget limit)\n";
    }
    model = std::move(c.model);
  } else {
    ctx.consumable = &btf.value();  // read for this encode alone: below, only its shape is used
    model = codec->encode(btf.value(), params, ctx);
  }
  if (!model.ok()) return fail(g, model.status().with_context(a.in));
  const double enc_s = seconds_since(t0);
  note_clamped(g, a.in, model.value()->stats());
  Status s = write_model(*model.value(), a.out);
  if (!s.ok()) return fail(g, s);
  const double ratio = double(btf->desc().num_values()) * 4.0 / double(std::filesystem::file_size(a.out));
  if (g.json) {
    json j{{"input", a.in}, {"output", a.out}, {"spec", model.value()->spec()}, {"read_seconds", read_s},
           {"encode_seconds", enc_s}, {"file_bytes", std::filesystem::file_size(a.out)}, {"ratio_vs_float32", ratio}};
    json st;
    print_stats(model.value()->stats(), &st, "encode_seconds");
    j["stats"] = st;
    if (!target_json.is_null()) j["target"] = target_json;
    std::cout << j.dump(2) << "\n";
  } else if (!g.quiet) {
    std::cout << "compressed " << a.in << " (" << btf->desc().summary() << ") with " << model.value()->spec() << "\n"
              << "  -> " << a.out << ", ratio " << ratio << " : 1 vs float32, encode " << enc_s << " s\n";
    print_stats(model.value()->stats(), nullptr, "encode_seconds");
  }
  return 0;
}

int cmd_decompress(const Global& g, const DecompressArgs& a) {
  if (Status s = require_input(a.in); !s.ok()) return fail(g, s);
  if (Status c = claim_output(a.out, {a.in}, {"-o", {".btfc", ".btf"}, true}); !c.ok()) return fail(g, c);
  if (int code = 0; decompress_streamed(g, a, code)) return code;
  auto model = open_model(a.in);
  if (!model.ok()) return fail(g, model.status());
  DecodeRequest req;
  req.lod = a.lod;
  if (!a.region.empty()) {
    auto r = parse_ints(a.region, "--region");
    if (!r.ok()) return fail(g, r.status());
    if (r->size() != 4) return fail(g, invalid_argument("--region: expected x,y,w,h"));
    req.x0 = (*r)[0], req.y0 = (*r)[1], req.width = (*r)[2], req.height = (*r)[3];
  }
  for (auto [text, dst, what] : {std::tuple{&a.lights, &req.lights, "--lights"}, std::tuple{&a.views, &req.views, "--views"}}) {
    if (text->empty()) continue;
    auto v = parse_ints(*text, what);
    if (!v.ok()) return fail(g, v.status());
    *dst = v.value();
  }
  auto t0 = Clock::now();
  Btf out;
  Status s = model.value()->decode(req, out);
  if (!s.ok()) return fail(g, s.with_context(a.in));
  const double dec_s = seconds_since(t0);
  s = write_btf(out, a.out, a.format == "png" ? ImageFormat::png : ImageFormat::exr);
  if (!s.ok()) return fail(g, s);
  if (g.json) std::cout << json{{"output", a.out}, {"desc", out.desc().summary()}, {"decode_seconds", dec_s}}.dump(2) << "\n";
  else if (!g.quiet) std::cout << "decoded " << a.in << " -> " << a.out << ": " << out.desc().summary() << " in " << dec_s << " s\n";
  return 0;
}

int cmd_eval(const Global& g, const EvalArgs& a) {
  if (Status s = require_input(a.in); !s.ok()) return fail(g, s);
  auto xy = parse_ints(a.texel, "--texel");
  if (!xy.ok()) return fail(g, xy.status());
  if (xy->size() != 2) return fail(g, invalid_argument("--texel: expected X,Y"));
  auto model = open_model(a.in);
  if (!model.ok()) return fail(g, model.status());
  const Model& m = *model.value();
  const BtfDesc& d = m.desc();
  const int x = (*xy)[0], y = (*xy)[1];
  if (x < 0 || y < 0 || x >= d.width || y >= d.height)
    return fail(g, invalid_argument("--texel " + a.texel + " is outside the " + std::to_string(d.width) + "x" + std::to_string(d.height) + " texels"));
  std::vector<float> out(size_t(d.channels));
  const bool measured = a.light.has_value() || a.view.has_value();
  if (measured == (!a.wl.empty() || !a.wv.empty()))
    return fail(g, invalid_argument("give either --light and --view (measured indices) or --wl and --wv (directions)"));
  if (measured) {
    if (!a.light || !a.view) return fail(g, invalid_argument("--light and --view go together"));
    if (*a.light < 0 || size_t(*a.light) >= d.num_lights() || *a.view < 0 || size_t(*a.view) >= d.num_views())
      return fail(g, invalid_argument("--light/--view index outside the direction sets (" + std::to_string(d.num_lights()) +
                                      " lights, " + std::to_string(d.num_views()) + " views)"));
    Status s = m.eval_lod(x, y, *a.light, *a.view, a.lod, out.data());
    if (!s.ok()) return fail(g, s);
  } else {
    if (a.lod != 0) return fail(g, invalid_argument("--lod works with --light/--view (measured directions)"));
    if (a.wl.empty() || a.wv.empty()) return fail(g, invalid_argument("--wl and --wv go together"));
    auto wl = parse_theta_phi(a.wl, "--wl");
    if (!wl.ok()) return fail(g, wl.status());
    auto wv = parse_theta_phi(a.wv, "--wv");
    if (!wv.ok()) return fail(g, wv.status());
    // Beyond the measured directions the value is extrapolated: said once, on stderr.
    std::string why;
    if (wl->z < 0 || wv->z < 0) why = "a direction below the horizon (theta > 90)";
    const double k_tol = std::cos(0.5 * 3.14159265358979323846 / 180.0);
    if (why.empty() && d.num_views() == 1 && dot3(wv.value(), d.views.dirs[0]) < k_tol)
      why = "--wv away from the model's one measured view";
    if (why.empty() && d.num_lights() == 1 && dot3(wl.value(), d.lights.dirs[0]) < k_tol)
      why = "--wl away from the model's one measured light";
    if (!why.empty() && !g.quiet) std::cerr << "warning: " << a.in << ": extrapolated evaluation: " << why << "\n";
    Status s = m.eval_dir(x, y, wl.value(), wv.value(), out.data());
    if (!s.ok()) return fail(g, s);
  }
  if (g.json) {
    std::cout << json{{"texel", {x, y}}, {"value", out}}.dump(2) << "\n";
  } else {
    for (size_t c = 0; c < out.size(); ++c) std::printf("%s%.9g", c ? " " : "", double(out[c]));
    std::printf("\n");
  }
  return 0;
}

int cmd_compare(const Global& g, const CompareArgs& a) {
  for (const std::string* p : {&a.a, &a.b})
    if (Status s = require_input(*p); !s.ok()) return fail(g, s);
  auto ra = read_btf(a.a);
  if (!ra.ok()) return fail(g, ra.status());
  auto rb = read_btf(a.b);
  if (!rb.ok()) return fail(g, rb.status());
  auto m = compare_btf(ra.value(), rb.value(), a.ssim);
  if (!m.ok()) return fail(g, m.status().with_context(a.a + " vs " + a.b));
  const Metrics& x = m.value();
  if (g.json) {
    json j{{"rmse", x.rmse}, {"rel_l2", num(x.rel_l2)}, {"psnr", num(x.psnr)}, {"psnr_peak", x.peak}, {"max_abs", x.max_abs}};
    if (a.ssim) j["mean_ssim"] = x.mean_ssim;
    std::cout << j.dump(2) << "\n";
  } else {
    std::printf("RMSE %.6g  relL2 %.6g  PSNR %.3f dB (peak %.6g)  max|err| %.6g", x.rmse, x.rel_l2, x.psnr, x.peak, x.max_abs);
    if (a.ssim) std::printf("  mean SSIM %.5f", x.mean_ssim);
    std::printf("\n");
  }
  return 0;
}

int cmd_relight(const Global& g, const RelightArgs& a) {
  if (Status s = require_input(a.in); !s.ok()) return fail(g, s);
  if (Status c = claim_output(a.out, {a.in, a.env}, {"-o", {".exr", ".png"}}); !c.ok()) return fail(g, c);
  auto model = open_model(a.in);
  if (!model.ok()) return fail(g, model.status());
  auto view = parse_theta_phi(a.view, "--view");
  if (!view.ok()) return fail(g, view.status());
  auto t0 = Clock::now();
  auto env = read_environment(a.env, a.order);
  if (!env.ok()) return fail(g, env.status());
  const double project_s = seconds_since(t0);
  t0 = Clock::now();
  const int w = model.value()->desc().width, h = model.value()->desc().height;
  auto img = model.value()->relight(env.value(), view.value());
  if (!img.ok()) return fail(g, img.status().with_context(a.in));
  const double relight_s = seconds_since(t0);
  RgbImage rgb{w, h, std::move(img).value()};
  Status s = ends_with(a.out, ".png") ? write_rgb_image(a.out, rgb) : write_rgb_exr(a.out, w, h, rgb.rgb);
  if (!s.ok()) return fail(g, s);
  if (g.json)
    std::cout << json{{"output", a.out}, {"width", w}, {"height", h}, {"sh_order", a.order}, {"project_seconds", project_s},
                      {"relight_seconds", relight_s}}.dump(2) << "\n";
  else if (!g.quiet)
    std::cout << "relit " << a.in << " under " << a.env << " (SH order " << a.order << ", projection " << project_s << " s, relight "
              << relight_s << " s) -> " << a.out << " (" << w << "x" << h << ")\n";
  return 0;
}

int cmd_convert(const Global& g, const ConvertArgs& a) {
  if (Status s = require_input(a.in); !s.ok()) return fail(g, s);
  if (Status c = claim_output(a.out, {a.in}, {"-o", {".btf", ".btfc"}}); !c.ok()) return fail(g, c);
  auto model = open_model(a.in);
  if (!model.ok()) return fail(g, model.status());
  Status s;
  if (ends_with(a.out, ".btf")) {
    // Bonn's format holds factorizations only: say so with the file's name, not the writer's
    // "not an fmf model" after the model's spec.
    auto spec = parse_spec_string(model.value()->spec());
    if (spec.ok() && spec->codec != "fmf")
      return fail(g, unsupported(a.in + ": codec " + spec->codec + "; a Bonn .btf holds fmf models only (FMF, DFMF): keep it as .btfc"));
    s = write_bonn(*model.value(), a.out, a.precision == "half");
  } else if (ends_with(a.out, ".btfc")) {
    auto spec = parse_spec_string(model.value()->spec());
    const Codec* codec = spec.ok() ? find_codec(spec->codec) : nullptr;
    if (!codec) return fail(g, unsupported(a.in + ": its model cannot be stored as .btfc"));
    s = save_model(*model.value(), *codec, a.out);
  } else {
    return fail(g, invalid_argument("convert: the output must end in .btf (Bonn) or .btfc"));
  }
  if (!s.ok()) return fail(g, s);
  if (g.json) std::cout << json{{"input", a.in}, {"output", a.out}}.dump(2) << "\n";
  else if (!g.quiet) std::cout << "converted " << a.in << " -> " << a.out << "\n";
  return 0;
}

}  // namespace btfc::cli
