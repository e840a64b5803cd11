// `btfc bsvtf` (write the BSVTF streaming file of an fmf model) and `btfc tilecache` (run the
// offline tile-cache simulator on one). The algorithms live in formats/bsvtf/bsvtf.h and
// formats/bsvtf/tile_cache.h; this file parses, calls and prints.
#include <CLI/CLI.hpp>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>

#include "cli/commands.h"
#include "cli/outputs.h"
#include "core/params.h"
#include "formats/bsvtf/bsvtf.h"
#include "formats/bsvtf/tile_cache.h"
#include "formats/btf_io.h"

namespace btfc::cli {
namespace {

using nlohmann::json;
json num(double v) { return std::isfinite(v) ? json(v) : json(nullptr); }

// Bytes for people: tiles and packets are KiB-sized, files MiB-sized.
std::string human(uint64_t b) {
  char buf[32];
  if (b < 1024) std::snprintf(buf, sizeof buf, "%llu B", (unsigned long long)b);
  else if (b < (1u << 20)) std::snprintf(buf, sizeof buf, "%.1f KiB", double(b) / 1024);
  else std::snprintf(buf, sizeof buf, "%.2f MiB", double(b) / double(1 << 20));
  return buf;
}

struct BsvtfArgs {
  std::string in, out;
  int quality = BsvtfOptions{}.quality, tile = BsvtfOptions{}.tile;
};

struct TileCacheArgs {
  std::string in, csv, screen = "320x240", path = "fly";
  std::vector<size_t> cache_tiles;  // empty: a sweep from one tile per texture to all tiles
  int frames = 60, light = -1, view = -1;
  uint64_t bandwidth = 0;
};

int cmd_bsvtf(const Global& g, const BsvtfArgs& a) {
  if (Status s = require_input(a.in); !s.ok()) return fail(g, s);
  if (Status c = claim_output(a.out, {a.in}, {"-o", {".bsvtf"}}); !c.ok()) return fail(g, c);
  auto model = open_model(a.in);
  if (!model.ok()) return fail(g, model.status());
  if (auto spec = parse_spec_string((*model)->spec()); spec.ok() && spec->codec != "fmf")
    return fail(g, unsupported(a.in + ": codec " + spec->codec + "; BSVTF streams fmf models only (encode with -c fmf)"));
  BsvtfOptions o;
  o.quality = a.quality, o.tile = a.tile;
  BsvtfReport r;
  Status s = write_bsvtf(**model, o, a.out, &r);
  if (!s.ok()) return fail(g, s);
  const double ratio_tiles = double(r.tile_raw_half_bytes) / double(r.tile_bytes);
  const double ratio_f32 = double(r.eigen_f32_bytes) / double(r.tile_bytes), ratio_f16 = double(r.eigen_f16_bytes) / double(r.tile_bytes);
  if (g.json) {
    json blocks = json::object();
    for (const auto& [name, p] : r.block_psnr) blocks[name] = num(p);
    std::cout << json{{"input", a.in},          {"output", a.out},           {"quality", a.quality},
                      {"tile", a.tile},          {"textures", r.textures},    {"tiles", r.tiles},
                      {"levels", r.levels},      {"file_bytes", r.file_bytes}, {"header_bytes", r.header_bytes},
                      {"tile_bytes", r.tile_bytes}, {"packet_bytes", r.packet_bytes}, {"tile_raw_half_bytes", r.tile_raw_half_bytes},
                      {"eigen_f32_bytes", r.eigen_f32_bytes}, {"eigen_f16_bytes", r.eigen_f16_bytes},
                      {"ratio_tiles_vs_half", ratio_tiles}, {"ratio_vs_f32", ratio_f32}, {"ratio_vs_f16", ratio_f16},
                      {"psnr", num(r.psnr)},     {"block_psnr", blocks},      {"rel_l2", r.rel_l2},
                      {"max_abs", r.max_abs},    {"seconds", r.seconds}}
                     .dump(2)
              << "\n";
    return 0;
  }
  if (g.quiet) return 0;
  std::printf("%s: %zu tiles in %d levels (%zu virtual textures of 4 eigen-textures), %s\n", a.out.c_str(), r.tiles, r.levels, r.textures,
              human(r.file_bytes).c_str());
  std::printf("  tiles %s: %.2f:1 vs the tiles as half floats (%s, borders included)\n", human(r.tile_bytes).c_str(), ratio_tiles,
              human(r.tile_raw_half_bytes).c_str());
  std::printf("  eigen-textures: %.2f:1 vs float32 (%s), %.2f:1 vs half (%s)\n", ratio_f32, human(r.eigen_f32_bytes).c_str(), ratio_f16,
              human(r.eigen_f16_bytes).c_str());
  std::printf("  eigen-ABRDF packets %s, header + directory %s\n", human(r.packet_bytes).c_str(), human(r.header_bytes).c_str());
  std::printf("  PSNR %.2f dB (peak = block range;", r.psnr);
  for (const auto& [name, p] : r.block_psnr) std::printf(" %s %.2f", name.c_str(), p);
  std::printf("), relative L2 %.3g, max |error| %.3g\n  built in %.2f s\n", r.rel_l2, r.max_abs, r.seconds);
  return 0;
}

Status write_csv(const std::string& path, const std::vector<std::pair<size_t, TileCacheRun>>& runs) {
  if (path == "-") {
    std::cout << "cache_tiles,frame,resident,working_set,adds,swaps,evictions,covered,packets,bytes,error,ssim\n";
    for (const auto& [slots, run] : runs)
      for (const TileCacheFrame& x : run.frames)
        std::cout << slots << ',' << x.frame << ',' << x.resident << ',' << x.working_set << ',' << x.adds << ',' << x.swaps << ','
                  << x.evictions << ',' << x.covered << ',' << x.packets << ',' << x.bytes << ',' << x.error << ',' << x.ssim << '\n';
    return std::cout.flush() ? Status{} : io_error("stdout: cannot write");
  }
  const std::string tmp = path + ".tmp-" + std::to_string(::getpid());
  {
    std::ofstream f(tmp, std::ios::trunc);
    f << "cache_tiles,frame,resident,working_set,adds,swaps,evictions,covered,packets,bytes,error,ssim\n";
    for (const auto& [slots, run] : runs)
      for (const TileCacheFrame& x : run.frames)
        f << slots << ',' << x.frame << ',' << x.resident << ',' << x.working_set << ',' << x.adds << ',' << x.swaps << ',' << x.evictions << ','
          << x.covered << ',' << x.packets << ',' << x.bytes << ',' << x.error << ',' << x.ssim << '\n';
    if (!f.flush()) {
      std::remove(tmp.c_str());
      return io_error(path + ": cannot write");
    }
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    std::remove(tmp.c_str());
    return io_error(path + ": cannot rename the finished file into place");
  }
  return {};
}

int cmd_tilecache(const Global& g, const TileCacheArgs& a) {
  if (Status s = require_input(a.in); !s.ok()) return fail(g, s);
  if (a.csv == "-" && g.json) return fail(g, invalid_argument("--json and --csv -: only one report can go to stdout"));
  if (!a.csv.empty())
    if (Status c = claim_output(a.csv, {a.in}, {"--csv", {".csv", ".txt"}, false, true}); !c.ok()) return fail(g, c);
  TileCacheOptions o;
  char x = 0, extra = 0;
  if (std::sscanf(a.screen.c_str(), "%d%c%d%c", &o.path.width, &x, &o.path.height, &extra) != 3 || x != 'x')
    return fail(g, invalid_argument("--screen: expected WIDTHxHEIGHT, got '" + a.screen + "'"));
  o.path.frames = a.frames, o.bandwidth = a.bandwidth, o.light = a.light, o.view = a.view;
  o.path.kind = a.path == "still" ? CameraPathOptions::Kind::still : CameraPathOptions::Kind::fly;
  auto file = BsvtfReader::open(a.in);
  if (!file.ok()) return fail(g, file.status());
  auto sim = TileCacheSim::make(*file);
  if (!sim.ok()) return fail(g, sim.status());
  std::vector<size_t> sizes = a.cache_tiles;
  if (sizes.empty()) {
    for (size_t n = sim->textures(); n < sim->tiles(); n *= 2) sizes.push_back(n);
    sizes.push_back(sim->tiles());
  }
  std::vector<std::pair<size_t, TileCacheRun>> runs;
  for (size_t n : sizes) {
    o.cache_tiles = n;
    auto run = sim->run(o);
    if (!run.ok()) return fail(g, run.status().with_context(a.in));
    runs.emplace_back(n, std::move(run).value());
  }
  if (!a.csv.empty()) {
    Status s = write_csv(a.csv, runs);
    if (!s.ok()) return fail(g, s);
    if (a.csv == "-") return 0;  // the CSV is the output
  }
  const uint64_t slot = sim->tile_slot_bytes();
  if (g.json) {
    json out = json::array();
    for (const auto& [n, run] : runs) {
      int adds = 0, swaps = 0, ev = 0;
      for (const TileCacheFrame& f : run.frames) adds += f.adds, swaps += f.swaps, ev += f.evictions;
      out.push_back({{"cache_tiles", n}, {"cache_bytes", n * slot}, {"mean_error", run.mean_error}, {"mean_ssim", run.mean_ssim},
                     {"final_ssim", run.frames.back().ssim}, {"bytes_streamed", run.bytes}, {"adds", adds}, {"swaps", swaps}, {"evictions", ev}});
    }
    std::cout << json{{"input", a.in}, {"tiles", sim->tiles()}, {"frames", a.frames}, {"path", a.path}, {"bandwidth", a.bandwidth}, {"runs", out}}.dump(2)
              << "\n";
    return 0;
  }
  std::printf("%s: %zu tiles, %zu virtual textures; %d frames (%s path, %dx%d), bandwidth %s per frame\n", a.in.c_str(), sim->tiles(),
              sim->textures(), a.frames, a.path.c_str(), o.path.width, o.path.height, a.bandwidth ? human(a.bandwidth).c_str() : "unlimited");
  std::printf("%11s %11s %11s %10s %10s %12s %7s %6s %6s\n", "cache_tiles", "cache_half", "mean_error", "mean_ssim", "last_ssim", "streamed",
              "adds", "swaps", "evict");
  for (const auto& [n, run] : runs) {
    int adds = 0, swaps = 0, ev = 0;
    for (const TileCacheFrame& f : run.frames) adds += f.adds, swaps += f.swaps, ev += f.evictions;
    std::printf("%11zu %11s %11.5f %10.4f %10.4f %12s %7d %6d %6d\n", n, human(n * slot).c_str(), run.mean_error, run.mean_ssim,
                run.frames.back().ssim, human(run.bytes).c_str(), adds, swaps, ev);
  }
  return 0;
}

}  // namespace

void add_bsvtf_commands(CLI::App& app, const Global& g, int& code) {
  auto b = std::make_shared<BsvtfArgs>();
  auto* bs = app.add_subcommand("bsvtf", "write the BSVTF streaming file of an fmf model (tiled, DCT-compressed eigen-textures, seed 000)");
  bs->add_option("model", b->in, "fmf model (.btfc or Bonn .btf)")->required();
  bs->add_option("-o,--output", b->out, "output FILE.bsvtf")->required();
  bs->add_option("--quality", b->quality, "JPEG-like quantisation quality")->check(CLI::Range(1, 100));
  bs->add_option("--tile", b->tile, "tile size in texels (the paper: 64; + 4-texel border, a multiple of 8)")->check(CLI::Range(8, 1024));
  bs->callback([&g, &code, b] { code = cmd_bsvtf(g, *b); });

  auto t = std::make_shared<TileCacheArgs>();
  auto* tc = app.add_subcommand("tilecache", "simulate the BSVTF tile cache along a camera path: error vs cache size, SSIM vs bytes streamed");
  tc->add_option("file", t->in, "FILE.bsvtf")->required();
  tc->add_option("--cache-tiles", t->cache_tiles, "cache sizes in tiles, comma-separated (default: doubling from one per texture to all)")
      ->delimiter(',')
      ->check(CLI::PositiveNumber);
  tc->add_option("--frames", t->frames, "frames of the camera path")->check(CLI::Range(1, 100000));
  tc->add_option("--csv", t->csv, "write one row per (cache size, frame) to this CSV file");
  tc->add_option("--bandwidth", t->bandwidth, "bytes streamed per frame at most (0 = unlimited)");
  tc->add_option("--path", t->path, "fly: from far above to close and grazing and back; still: the close grazing view")
      ->check(CLI::IsMember({"fly", "still"}));
  tc->add_option("--screen", t->screen, "screen WIDTHxHEIGHT in pixels");
  tc->add_option("--light", t->light, "light index used to shade the rendered sample (default: lights / 2)");
  tc->add_option("--view", t->view, "view index used to shade the rendered sample (default: 0)");
  tc->callback([&g, &code, t] { code = cmd_tilecache(g, *t); });
}

}  // namespace btfc::cli
