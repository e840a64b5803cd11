// `btfc export MODEL --to DIR`: GPU-ready textures, manifest and reference shader
// (formats/gpu/export.h), optionally cut to a scene's needs (--scene, core/scene.h).
#include <CLI/CLI.hpp>
#include <chrono>
#include <iostream>
#include <nlohmann/json.hpp>

#include "cli/commands.h"
#include "cli/outputs.h"
#include "formats/bsvtf/bsvtf_export.h"
#include "formats/exr/envmap.h"
#include "formats/btf_io.h"
#include "formats/gpu/export.h"

namespace btfc::cli {
namespace {

struct ExportArgs {
  std::string in, dir, env, scene, material;
  bool float32 = false, clamp_half = false, no_previews = false, no_bsvtf = false;
  int direction_map = 64, sh_order = 5, bsvtf_quality = BsvtfOptions{}.quality;
};

int cmd_export(const Global& g, const ExportArgs& a) {
  const auto t0 = std::chrono::steady_clock::now();
  if (Status s = require_input(a.in); !s.ok()) return fail(g, s);
  if (Status c = claim_output(a.dir, {a.in, a.env, a.scene}, {"--to", {}, true}); !c.ok()) return fail(g, c);
  auto model = open_model(a.in);
  if (!model.ok()) return fail(g, model.status());
  Model& m = *model.value();
  if (!a.env.empty()) {
    auto env = read_environment(a.env, a.sh_order);
    if (!env.ok()) return fail(g, env.status());
    if (Status s = m.attach_environment(env.value()); !s.ok()) return fail(g, s.with_context("--env"));
  }
  gpu::ExportOptions opt;
  opt.half = !a.float32;
  opt.clamp_half = a.clamp_half;
  opt.direction_map = a.direction_map;
  if (!a.scene.empty()) {
    auto sc = gpu::read_scene(a.scene, a.material);
    if (!sc.ok()) return fail(g, sc.status());
    opt.scene = sc.value();
  }
  auto bundle = gpu::build_export(m, opt);
  if (!bundle.ok()) return fail(g, bundle.status().with_context(a.in));
  BsvtfReport bsvtf;
  if (!a.no_bsvtf) {
    BsvtfOptions bo;
    bo.quality = a.bsvtf_quality;
    attach_bsvtf(bundle.value(), m, opt, bo, &bsvtf);
  }
  if (Status s = gpu::write_export_dir(bundle.value(), a.dir, !a.no_previews); !s.ok()) return fail(g, s);
  const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  for (const std::string& w : bundle->warnings) std::cerr << "warning: " << a.in << ": " << w << "\n";
  if (g.json) {
    nlohmann::json j = gpu::manifest_json(bundle.value());
    j.erase("btf");  // direction tables: in the manifest file
    j["directory"] = a.dir;
    j["seconds"] = secs;
    std::cout << j.dump(2) << "\n";
  } else if (!g.quiet) {
    std::cout << "exported " << a.in << " (" << bundle->spec << ") -> " << a.dir << "/ in " << secs << " s\n";
    for (const gpu::GpuTexture& t : bundle->textures)
      std::cout << "  " << t.name << ".ktx2  " << gpu::format_info(t.format).name << " " << t.width << " x " << t.height
                << (t.layers ? " x " + std::to_string(t.layers) + " layers" : std::string()) << ", " << t.num_levels() << " level(s), "
                << t.total_bytes() << " bytes" << (t.scale != 1 ? ", scale " + std::to_string(t.scale) : std::string()) << "\n";
    if (!bundle->scene_report.is_null()) std::cout << "  scene: " << bundle->scene_report.dump() << "\n";
    if (bsvtf.file_bytes)
      std::cout << "  model.bsvtf  " << bsvtf.tiles << " tiles, " << bsvtf.file_bytes << " bytes, eigen-texture PSNR " << bsvtf.psnr << " dB\n";
    std::cout << "  manifest.json, btf.frag" << (a.no_previews ? "" : ", previews/") << "; textures " << bundle->texture_bytes()
              << " bytes (model payload " << bundle->model_payload_bytes << ")\n";
  }
  return 0;
}

}  // namespace

void add_export_commands(CLI::App& app, const Global& g, int& code) {
  static ExportArgs a;
  auto* ex = app.add_subcommand("export", "write GPU-ready textures (KTX2), a JSON manifest and a GLSL reference shader for a model");
  ex->add_option("model", a.in, "model .btfc (fmf, lpyr, lpca, mlvq) or Bonn .btf")->required();
  ex->add_option("--to", a.dir, "output directory (created; an existing one needs --force)")->required();
  ex->add_flag("--float", a.float32, "store float data as RGBA32F instead of RGBA16F");
  ex->add_flag("--clamp-half", a.clamp_half, "clamp values beyond the half range (reported) instead of scaling the texture");
  ex->add_option("--direction-map", a.direction_map, "size of the parabolic direction index / weight maps")->check(CLI::Range(2, 1024));
  ex->add_option("--env", a.env, "lat-long EXR environment for codecs with precomputed radiance transfer (lpca, seed 002 section 5.1); others refuse it");
  ex->add_option("--sh-order", a.sh_order, "SH order of the --env projection")->check(CLI::Range(1, 12));
  ex->add_option("--scene", a.scene, "scene.json: footprints, light/view cones, GPU budget; keep only what the scene needs");
  ex->add_option("--material", a.material, "material of the scene file (default: the first)");
  ex->add_option("--bsvtf-quality", a.bsvtf_quality, "DCT quality of the BSVTF tiles written beside a factorization (fmf, Bonn FMF/DFMF), 1..100")->check(CLI::Range(1, 100));
  ex->add_flag("--no-bsvtf", a.no_bsvtf, "skip the BSVTF streaming file of a factorization");
  ex->add_flag("--no-previews", a.no_previews, "skip the EXR / PNG previews");
  ex->callback([&] { code = cmd_export(g, a); });
}

}  // namespace btfc::cli
