// btfc: the command-line front end. Parses arguments (CLI11) and dispatches to cli/commands.cpp.
#include <CLI/CLI.hpp>
#include <iostream>

#include "cli/commands.h"
#include "cli/docgen.h"
#include "cli/outputs.h"
#include "formats/image_set.h"
#include "core/blas_env.h"

namespace {
CLI::App* find_command(CLI::App& app, const std::string& name) {
  for (CLI::App* s : app.get_subcommands({}))
    if (s->check_name(name)) return s;
  return nullptr;
}
}  // namespace

int main(int argc, char** argv) {
  btfc::reexec_for_openblas(argc, argv);
  using namespace btfc::cli;
  install_interrupt_cleanup();  // SIGINT / SIGTERM: remove temporaries, keep old outputs (cli/outputs.h)
  CLI::App app{"btfc - compression toolkit for Bidirectional Texture Functions"};
  app.require_subcommand(1);
  Global g;
  for (int i = 0; i < argc; ++i) g.command_line += (i ? " " : "") + std::string(argv[i]);
  app.set_version_flag("--version", std::string("btfc ") + BTFC_VERSION);
  app.option_defaults()->always_capture_default();  // --help shows every default
  // Global options: accepted before or after the command, listed in every command's help
  // (added to each subcommand below, bound to the same variables).
  bool force = false, allow_partial = false;
  std::string device = "auto";
  auto add_globals = [&](CLI::App* a) {
    a->add_flag("--json", g.json, "machine-readable JSON output on stdout")->group("Global options");
    a->add_flag("-q,--quiet", g.quiet, "no progress bar or chatter")->group("Global options");
    a->add_flag("-f,--force", force, "replace an existing output (file or directory); never the input")->group("Global options");
    a->add_flag("--allow-partial", allow_partial, "read an image set with images missing from its UBO sampling (named on stderr)")
        ->group("Global options");
    a->add_option("--device", device, "where kernels run: cl (OpenCL, required), cpu (C++ reference), auto (OpenCL if it works)")
        ->check(CLI::IsMember({"auto", "cpu", "cl"}))
        ->group("Global options");
  };
  add_globals(&app);
  app.parse_complete_callback([&] {
    set_device(device);
    set_force(force);
    btfc::set_allow_partial_image_sets(allow_partial);
  });
  int code = 0;

  bool names_only = false;
  auto* codecs = app.add_subcommand("codecs", "list the registered codecs and their parameters");
  codecs->add_flag("--names", names_only, "only the names, one per line");
  codecs->callback([&] { code = cmd_codecs(g, names_only); });

  auto* devices = app.add_subcommand("devices", "list the OpenCL devices btfc can use");
  devices->callback([&] { code = cmd_devices(g); });

  SynthArgs sy;
  auto* synth = app.add_subcommand("synth", "write a deterministic synthetic BTF (height field, shadows, spatially varying material)");
  synth->add_option("-o,--output", sy.out, "output: FILE.btfc (raw) or a directory (UTIA image set)")->required();
  synth->add_option("--width", sy.width, "texels")->check(CLI::Range(1, 1 << 16));
  synth->add_option("--height", sy.height, "texels")->check(CLI::Range(1, 1 << 16));
  synth->add_option("--lights", sy.lights, "ubo2003 | ubo2014 | THETA,PHI (one direction, degrees)");
  synth->add_option("--views", sy.views, "ubo2003 | ubo2014 | THETA,PHI (one direction, degrees)");
  synth->add_option("--seed", sy.seed, "random seed");
  synth->add_option("--bump", sy.bump, "height-field amplitude (0 = flat)")->check(CLI::Range(0.0, 100.0));
  synth->add_option("--scale", sy.scale, "multiplies all values (HDR)")->check(CLI::Range(1e-30, 1e30));
  synth->add_option("--noise", sy.noise, "measurement noise: each value times max(0, 1 + noise x standard normal), independent per image")
      ->check(CLI::Range(0.0, 10.0));
  synth->add_option("--format", sy.format, "image-set format")->check(CLI::IsMember({"exr", "png"}));
  synth->callback([&] { code = cmd_synth(g, sy); });

  std::string info_path;
  bool verify = false;
  auto* info = app.add_subcommand("info", "describe a .btfc file or an image set");
  info->add_option("file", info_path, "FILE.btfc or image-set directory")->required();
  info->add_flag("--verify", verify, "read every tensor and check its checksum");
  info->callback([&] { code = cmd_info(g, info_path, verify); });

  CompressArgs ca;
  auto* compress = app.add_subcommand("compress", "compress a BTF into a model (.btfc)");
  compress->add_option("input", ca.in, "image-set directory, raw .btfc, model .btfc or Bonn .btf")->required();
  compress->add_option("-c,--codec", ca.spec, "codec spec string, e.g. fmf:rank=32:precision=half")->required();
  compress->add_option("-o,--output", ca.out, "output .btfc, or .btf (Bonn DFMF / FMF, fmf models)")->required();
  compress->add_option("--seed", ca.seed, "random seed (randomized algorithms)");
  auto* tp = compress->add_option("--target-psnr", ca.target_psnr, "search the codec's quality knob for the cheapest setting reaching this PSNR (dB)");
  auto* ts = compress->add_option("--target-ssim", ca.target_ssim, "... reaching this mean SSIM over the BTF's images")->check(CLI::Range(0.0, 1.0));
  auto* tb = compress->add_option("--max-bytes", ca.max_bytes, "... the most accurate setting whose .btfc file fits in this many bytes")->check(CLI::PositiveNumber);
  tp->excludes(ts)->excludes(tb);
  ts->excludes(tb);
  compress->add_option("--max-memory", ca.max_memory, "BTF data held in memory at most (e.g. 2G; default 80% of available RAM); larger inputs stream (fmf)");
  compress->add_option("--work-file", ca.work_file, "out-of-core working file (a Bonn BDI .btf), kept and reused; default: a temporary next to the output");
  compress->callback([&] { code = cmd_compress(g, ca); });

  DecompressArgs da;
  auto* decompress = app.add_subcommand("decompress", "decode a model, fully or a region / direction subset");
  decompress->add_option("input", da.in, "model .btfc")->required();
  decompress->add_option("-o,--output", da.out, "FILE.btfc (raw) or a directory (UTIA image set)")->required();
  decompress->add_option("--region", da.region, "x,y,w,h texel rectangle");
  decompress->add_option("--lights", da.lights, "comma-separated light indices");
  decompress->add_option("--views", da.views, "comma-separated view indices");
  decompress->add_option("--format", da.format, "image-set format")->check(CLI::IsMember({"exr", "png"}));
  decompress->add_option("--max-memory", da.max_memory, "decoded data held in memory at most; larger outputs (.btfc, Bonn .btf, image sets) are written in parts");
  decompress->add_option("--lod", da.lod, "level of detail (lpyr): 0 = full detail")->check(CLI::Range(0.0, 64.0));
  decompress->callback([&] { code = cmd_decompress(g, da); });

  EvalArgs ea;
  int light = -1, view = -1;
  auto* eval = app.add_subcommand("eval", "evaluate a model at one texel, at measured or arbitrary directions");
  eval->add_option("input", ea.in, "model .btfc")->required();
  eval->add_option("--texel", ea.texel, "X,Y")->required();
  auto* ol = eval->add_option("--light", light, "measured light index");
  auto* ov = eval->add_option("--view", view, "measured view index");
  eval->add_option("--wl", ea.wl, "light direction THETA,PHI in degrees (interpolated)");
  eval->add_option("--wv", ea.wv, "view direction THETA,PHI in degrees (interpolated)");
  eval->add_option("--lod", ea.lod, "level of detail (lpyr), with --light/--view: 0 = full detail")->check(CLI::Range(0.0, 64.0));
  eval->callback([&] {
    if (ol->count()) ea.light = light;
    if (ov->count()) ea.view = view;
    code = cmd_eval(g, ea);
  });

  CompareArgs cm;
  bool no_ssim = false;
  auto* compare = app.add_subcommand("compare", "error metrics between two BTFs (RMSE, relative L2, PSNR, mean SSIM)");
  compare->add_option("reference", cm.a, "reference BTF (image set, raw or model .btfc)")->required();
  compare->add_option("test", cm.b, "test BTF")->required();
  compare->add_flag("--no-ssim", no_ssim, "skip SSIM");
  compare->callback([&] {
    cm.ssim = !no_ssim;
    code = cmd_compare(g, cm);
  });

  ConvertArgs cv;
  auto* convert = app.add_subcommand("convert", "convert a model between .btfc and Bonn .btf (DFMF / FMF)");
  convert->add_option("input", cv.in, "model .btfc or Bonn .btf")->required();
  convert->add_option("-o,--output", cv.out, "OUT.btf (Bonn: DFMF for per-channel models, FMF for rgb) or OUT.btfc")->required();
  convert->add_option("--precision", cv.precision, "Bonn scalars")->check(CLI::IsMember({"half", "float"}));
  convert->callback([&] { code = cmd_convert(g, cv); });

  RelightArgs ra;
  auto* relight = app.add_subcommand("relight", "render a model's flat sample under a lat-long HDR environment (spherical harmonics; lpca by its precomputed radiance transfer, other codecs by quadrature over the measured lights)");
  relight->add_option("input", ra.in, "model .btfc or Bonn .btf (any codec)")->required();
  relight->add_option("--env", ra.env, "lat-long environment map (EXR, row 0 = zenith)")->required();
  relight->add_option("--view", ra.view, "view direction THETA,PHI in degrees")->required();
  relight->add_option("-o,--output", ra.out, "output image (EXR, one pixel per texel)")->required();
  relight->add_option("--order", ra.order, "spherical-harmonic bands of the environment")->check(CLI::Range(1, 16));
  relight->callback([&] { code = cmd_relight(g, ra); });

  BenchArgs ba;
  bool no_header = false;
  auto* bench = app.add_subcommand("bench", "measure codecs and parameter sweeps on a BTF. Columns: ratio = float32 bytes / payload bytes; bpv = payload bits per "
      "value; RMSE, PSNR (dB, peak = the data's maximum); SSIM = mean SSIM over the BTF's images; rSSIM = SSIM of rendered "
      "flat and sphere images (n/a with --no-renders); enc s / dec s = encode / full decode seconds; Meval/s = million "
      "interpolated evaluations per second; peak MB = peak resident memory");
  bench->add_option("input", ba.in, "BTF (image set, raw .btfc or Bonn .btf)")->required();
  bench->add_option("-c,--codec", ba.specs, "codec spec (repeatable); a comma list sweeps a parameter: fmf:rank=4,8,16")->required();
  bench->add_option("--label", ba.label, "data label in the table (default: the input's name)");
  bench->add_option("--seed", ba.seed, "random seed");
  bench->add_option("--csv", ba.csv, "write the runs as CSV to this file");
  bench->add_flag("--append", ba.append, "append to the --csv file instead of replacing it");
  bench->add_option("--json-out", ba.json_out, "write the JSON report to this file");
  bench->add_option("--renders", ba.renders_dir, "write a labelled PNG panel per run and scene here: original | decoded | error x5 with its colour scale and range");
  bench->add_flag("--pareto", ba.pareto, "list which run wins at each byte budget (PSNR and SSIM fronts)");
  bench->add_flag("--no-renders", ba.no_renders, "skip the rendered-image SSIM");
  bench->add_option("--throughput-queries", ba.throughput_queries, "random interpolated evaluations per timing round (0 = skip)");
  bench->add_option("--max-memory", ba.max_memory, "BTF data held in memory at most; larger inputs stream (fmf; no SSIM)");
  bench->add_flag("--no-header", no_header, "omit the table header");
  bench->callback([&] {
    ba.header = !no_header;
    code = cmd_bench(g, ba);
  });

  RenderArgs rn;
  auto* rend = app.add_subcommand("render", "render a BTF or model: flat sample or sphere, point / directional light or lat-long environment");
  rend->add_option("input", rn.in, "model .btfc, raw .btfc, image set or Bonn .btf")->required();
  rend->add_option("-o,--output", rn.out, "output image (.png sRGB 8-bit, or .exr linear)")->required();
  rend->add_option("--shape", rn.shape, "flat (one pixel per texel) or sphere")->check(CLI::IsMember({"flat", "sphere"}));
  rend->add_option("--view", rn.view, "direction towards the camera, THETA,PHI degrees");
  rend->add_option("--light", rn.light, "direction towards the light, THETA,PHI degrees");
  rend->add_option("--distance", rn.distance, "point light at this distance (sample widths / sphere radii); 0 = directional")->check(CLI::Range(0.0, 1e6));
  rend->add_option("--env", rn.env, "lat-long EXR environment (row 0 = zenith) instead of the light");
  rend->add_option("--intensity", rn.intensity, "light scale")->check(CLI::Range(0.0, 1e30));
  rend->add_option("--size", rn.size, "sphere image size in pixels")->check(CLI::Range(1, 8192));
  rend->add_option("--tiles", rn.tiles, "sphere: texture repeats in theta (twice as many in phi)")->check(CLI::Range(1, 1024));
  rend->add_option("--exposure", rn.exposure, "exposure in stops: values x 2^EV (PNG and EXR)")->check(CLI::Range(-64.0, 64.0));
  rend->add_option("--tonemap", rn.tonemap, "none (a PNG clips at 1) or reinhard (L / (1 + L) per pixel: HDR highlights stay visible)")
      ->check(CLI::IsMember({"none", "reinhard"}));
  rend->callback([&] { code = cmd_render(g, rn); });

  add_export_commands(app, g, code);
  add_bsvtf_commands(app, g, code);
  add_view_command(app, g, code);

  std::string help_cmd, doc_kind;
  auto* help = app.add_subcommand("help", "show the help of a command (btfc help COMMAND) or of btfc");
  help->add_option("command", help_cmd, "the command");
  help->callback([&] {
    if (help_cmd.empty()) {
      std::cout << app.help();
      return;
    }
    CLI::App* sub = find_command(app, help_cmd);
    if (!sub || sub->get_group().empty()) {
      std::cerr << "error: unknown command '" << help_cmd << "' (btfc --help lists the commands)\n";
      code = 1;
      return;
    }
    std::cout << sub->help();
  });
  auto* completion = app.add_subcommand("completion", "print a shell completion script: bash or zsh");
  completion->add_option("shell", doc_kind, "bash | zsh")->required()->check(CLI::IsMember({"bash", "zsh"}));
  completion->callback([&] { std::cout << (doc_kind == "bash" ? bash_completion(app) : zsh_completion(app)); });
  auto* man = app.add_subcommand("man", "print the man page (roff), generated from the help");
  man->callback([&] { std::cout << man_page(app, BTFC_VERSION); });

  for (CLI::App* sub : app.get_subcommands({})) add_globals(sub);

  // "btfc foo": name the unknown command (CLI11 would say a subcommand is required).
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--device") {
      ++i;
      continue;
    }
    if (arg.empty() || arg[0] == '-') continue;
    if (!find_command(app, arg)) {
      std::cerr << "error: unknown command '" << arg << "' (btfc --help lists the commands)\n";
      return 1;
    }
    break;
  }

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    finish_outputs(false);
    const int rc = app.exit(e);
    return rc == 0 ? 0 : 1;
  }
  finish_outputs(code == 0);
  return code;
}
