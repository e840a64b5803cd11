// BSVTF benchmark (seed 000 sections 6 and 7; docs/benchmarks.md "BSVTF").
//
// For an fmf model: writes the BSVTF at several qualities and reports the DCT tile compression
// ratio (against the tiles as half floats, the paper's "up to 6:1 with no perceivable
// artifacts"), the ratio against the eigen-textures as float32 / half, the eigen-texture PSNR,
// build and full-decode time, and -- to judge "visible" -- the BTF decoded from the BSVTF against
// the fmf model itself on a subset of (light, view) images (PSNR, mean SSIM) and a rendered flat
// sample (SSIM). With --original (raw .btfc or image set), both are also compared with the
// uncompressed BTF. Then the tile cache (formats/bsvtf/tile_cache.h) on the --cache-quality file: error / SSIM against cache size on
// the fly-through path (Fig. 4), and SSIM against bytes streamed on the still path with a
// bandwidth limit (Fig. 5).
//
//   bench_bsvtf MODEL.btfc OUTDIR LABEL [--original BTF] [--tile 64] [--qualities 10,25,...]
//               [--cache-quality 95] [--frames 60] [--bandwidth 32768]
// Writes OUTDIR/bsvtf_{quality,cache,stream}_LABEL.csv and prints markdown tables.
//   bench_bsvtf --build-only WIDTH HEIGHT C OUTDIR   (build time at the paper's sizes; below)
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string>

#include "codecs/codec.h"
#include "formats/bsvtf/bsvtf.h"
#include "codecs/fmf/fmf.h"
#include "formats/bsvtf/tile_cache.h"
#include "codecs/render.h"
#include "core/blas_env.h"
#include "core/metrics.h"
#include "formats/btf_io.h"

using namespace btfc;

namespace {

double now_s() { return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count(); }

[[noreturn]] void die(const Status& s) {
  std::fprintf(stderr, "error: %s\n", s.message().c_str());
  std::exit(1);
}
template <class T>
T take(Result<T> r) {
  if (!r.ok()) die(r.status());
  return std::move(r).value();
}

// Every k-th direction index, at most `n` of them.
std::vector<int> spread(size_t count, size_t n) {
  std::vector<int> out;
  const size_t step = std::max<size_t>(1, (count + n - 1) / n);
  for (size_t i = 0; i < count; i += step) out.push_back(int(i));
  return out;
}

// The fmf model the BSVTF decodes to (decoded eigen-textures and eigen-ABRDF packets).
std::unique_ptr<Model> decoded_model(const Model& fmf, const BsvtfReader& r, double& seconds) {
  const double t0 = now_s();
  std::vector<FmfFactors> blocks;
  for (size_t b = 0; b < r.blocks().size(); ++b) {
    FmfFactors f;
    f.name = r.blocks()[b].name, f.C = int(r.blocks()[b].components);
    f.SxV = take(r.decode_eigen_textures(int(b)));
    f.U = take(r.decode_eigen_abrdfs(int(b)));
    f.S.assign(size_t(f.C), 1.0f);
    blocks.push_back(std::move(f));
  }
  seconds = now_s() - t0;
  return take(make_fmf_model(fmf.desc(), r.color_model(), std::move(blocks), nullptr, nullptr, false));
}

RgbImage flat_render(const Model& m) {
  RenderSettings s;
  s.light = dir_from_theta_phi(30 * 3.14159265358979 / 180, 0.5);
  return take(render(m.desc(), model_evaluator(m), s));
}

// --build-only W H C: build time alone on an fmf model made from synthetic factors (smooth
// eigen-textures plus texel noise, amplitude decaying like singular values; random U with the
// UBO2003 row count), so the paper's sizes (512^2 .. 2048^2, C = 100) need no BTF or SVD.
int build_only(int w, int h, int C, const std::string& outdir) {
  BtfDesc d;
  d.width = w, d.height = h, d.lights = DirectionSet::ubo2003(), d.views = DirectionSet::ubo2003();
  FmfFactors f;
  f.name = "rgb", f.C = C;
  f.U.resize(d.abrdf_size() * size_t(C));
  uint64_t z = 88172645463325252ull;
  auto rnd = [&z] { return (z ^= z << 13, z ^= z >> 7, z ^= z << 17, double(z >> 11) / double(1ull << 53) - 0.5); };
  for (float& u : f.U) u = float(rnd() * 0.02);
  f.SxV.resize(size_t(w) * size_t(h) * size_t(C));
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < C; ++c)
        f.SxV[(size_t(y) * size_t(w) + size_t(x)) * size_t(C) + size_t(c)] =
            float(std::pow(0.93, c) * (std::sin(0.05 * (c % 7 + 1) * x) * std::cos(0.03 * (c % 5 + 1) * y) + 0.3 * rnd()));
  f.S.assign(size_t(C), 1.0f);
  std::vector<FmfFactors> blocks;
  blocks.push_back(std::move(f));
  auto m = take(make_fmf_model(d, 0, std::move(blocks), nullptr, nullptr, true));
  BsvtfReport r;
  if (Status s = write_bsvtf(*m, BsvtfOptions{}, outdir + "/build_only.bsvtf", &r); !s.ok()) die(s);
  std::printf("| %d x %d | %d | %zu | %.1f MB | %.2f | %.2f | %.2f s | %.0f |\n", w, h, C, r.tiles, r.file_bytes / 1e6,
              double(r.tile_raw_half_bytes) / r.tile_bytes, r.psnr, r.seconds, r.tiles / r.seconds);
  std::remove((outdir + "/build_only.bsvtf").c_str());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  reexec_for_openblas(argc, argv);
  if (argc == 6 && std::string(argv[1]) == "--build-only") return build_only(std::stoi(argv[2]), std::stoi(argv[3]), std::stoi(argv[4]), argv[5]);
  if (argc < 4) {
    std::fprintf(stderr, "usage: bench_bsvtf MODEL.btfc OUTDIR LABEL [--original BTF] [--tile 64] [--qualities 10,25,50] "
                         "[--cache-quality 95] [--frames 60] [--bandwidth 32768]\n");
    return 1;
  }
  const std::string model_path = argv[1], outdir = argv[2], label = argv[3];
  std::string original, qualities = "10,25,50,75,85,90,95,100";
  int tile = 64, cache_quality = 95, frames = 60;
  uint64_t bandwidth = 32768;
  for (int i = 4; i + 1 < argc; i += 2) {
    const std::string k = argv[i], v = argv[i + 1];
    if (k == "--original") original = v;
    else if (k == "--tile") tile = std::stoi(v);
    else if (k == "--qualities") qualities = v;
    else if (k == "--cache-quality") cache_quality = std::stoi(v);
    else if (k == "--frames") frames = std::stoi(v);
    else if (k == "--bandwidth") bandwidth = std::stoull(v);
    else die(invalid_argument("unknown option " + k));
  }
  auto rd = take(ContainerReader::open(model_path));
  auto model = take(load_model(rd));
  const BtfDesc& d = model->desc();
  std::printf("# %s: %s, %s\n", label.c_str(), d.summary().c_str(), model->spec().c_str());

  // The comparison subset: up to 9 lights x 5 views.
  DecodeRequest sub;
  sub.lights = spread(d.num_lights(), 9), sub.views = spread(d.num_views(), 5);
  Btf fmf_sub, orig_sub;
  if (Status s = model->decode(sub, fmf_sub); !s.ok()) die(s);
  const RgbImage fmf_img = flat_render(*model);
  Metrics fmf_vs_orig;
  if (!original.empty()) {
    Btf full = take(read_btf(original));
    auto req = take(resolve_request(full.desc(), sub));
    orig_sub = take(Btf::create(req.desc));
    for (size_t t = 0; t < req.desc.num_texels(); ++t)
      for (size_t v = 0; v < req.views.size(); ++v)
        for (size_t l = 0; l < req.lights.size(); ++l)
          for (int c = 0; c < d.channels; ++c)
            orig_sub.abrdf(t)[req.desc.row(l, v, size_t(c))] = full.abrdf(t)[d.row(size_t(req.lights[l]), size_t(req.views[v]), size_t(c))];
    fmf_vs_orig = take(compare_btf(orig_sub, fmf_sub, true));
    std::printf("fmf model vs original (%zu images): PSNR %.2f dB, mean SSIM %.4f\n\n", req.desc.num_images(), fmf_vs_orig.psnr, fmf_vs_orig.mean_ssim);
  }

  std::ofstream qcsv(outdir + "/bsvtf_quality_" + label + ".csv");
  qcsv << "quality,file_bytes,tile_bytes,packet_bytes,tile_ratio_half,ratio_f32,ratio_f16,eigen_psnr,rel_l2,btf_psnr_vs_fmf,btf_ssim_vs_fmf,"
          "render_ssim_vs_fmf,btf_psnr_vs_orig,btf_ssim_vs_orig,build_s,decode_s\n";
  std::printf("| quality | file | tiles : half tiles | : f32 eigen-tex | : half eigen-tex | eigen PSNR dB | BTF PSNR vs fmf | SSIM vs fmf | render SSIM | %sbuild s | decode s |\n",
              original.empty() ? "" : "PSNR vs orig | ");
  std::printf("|---|---|---|---|---|---|---|---|---|%s---|---|\n", original.empty() ? "" : "---|");
  std::stringstream qs(qualities);
  for (std::string item; std::getline(qs, item, ',');) {
    const int q = std::stoi(item);
    BsvtfOptions o;
    o.quality = q, o.tile = tile;
    const std::string path = outdir + "/" + label + "_q" + std::to_string(q) + ".bsvtf";
    BsvtfReport rep;
    if (Status s = write_bsvtf(*model, o, path, &rep); !s.ok()) die(s);
    auto r = take(BsvtfReader::open(path));
    double decode_s = 0;
    auto dec = decoded_model(*model, r, decode_s);
    Btf dec_sub;
    if (Status s = dec->decode(sub, dec_sub); !s.ok()) die(s);
    const Metrics vs_fmf = take(compare_btf(fmf_sub, dec_sub, true));
    const double rssim = render_ssim(fmf_img, flat_render(*dec));
    Metrics vs_orig;
    if (!original.empty()) vs_orig = take(compare_btf(orig_sub, dec_sub, true));
    const double tr = double(rep.tile_raw_half_bytes) / rep.tile_bytes, r32 = double(rep.eigen_f32_bytes) / rep.tile_bytes,
                 r16 = double(rep.eigen_f16_bytes) / rep.tile_bytes;
    qcsv << q << ',' << rep.file_bytes << ',' << rep.tile_bytes << ',' << rep.packet_bytes << ',' << tr << ',' << r32 << ',' << r16 << ','
         << rep.psnr << ',' << rep.rel_l2 << ',' << vs_fmf.psnr << ',' << vs_fmf.mean_ssim << ',' << rssim << ','
         << (original.empty() ? NAN : vs_orig.psnr) << ',' << (original.empty() ? NAN : vs_orig.mean_ssim) << ',' << rep.seconds << ',' << decode_s << '\n';
    char orig_col[64] = "";
    if (!original.empty()) std::snprintf(orig_col, sizeof orig_col, "%.2f | ", vs_orig.psnr);
    std::printf("| %d | %.2f MB | %.2f | %.2f | %.2f | %.2f | %.2f | %.4f | %.4f | %s%.2f | %.2f |\n", q, rep.file_bytes / 1e6, tr, r32, r16, rep.psnr,
                vs_fmf.psnr, vs_fmf.mean_ssim, rssim, orig_col, rep.seconds, decode_s);
    std::fflush(stdout);
  }

  // Tile cache on the --cache-quality file.
  const std::string cpath = outdir + "/" + label + "_q" + std::to_string(cache_quality) + ".bsvtf";
  auto cr = take(BsvtfReader::open(cpath));
  auto sim = take(TileCacheSim::make(cr));
  std::printf("\nTile cache, %s (%zu tiles, %zu virtual textures, %d-texel tiles), fly path, %d frames, 320x240:\n\n", cpath.c_str(), sim.tiles(),
              sim.textures(), tile, frames);
  std::printf("| cache tiles | cache (half) | mean error | mean SSIM | streamed |\n|---|---|---|---|---|\n");
  std::ofstream ccsv(outdir + "/bsvtf_cache_" + label + ".csv");
  ccsv << "cache_tiles,cache_bytes,mean_error,mean_ssim,bytes\n";
  std::vector<size_t> sizes;
  for (size_t n = sim.textures(); n < sim.tiles(); n = n * 3 / 2 + 1) sizes.push_back(n);
  sizes.push_back(sim.tiles());
  const double t0 = now_s();
  for (size_t n : sizes) {
    TileCacheOptions o;
    o.cache_tiles = n, o.path.frames = frames;
    auto run = take(sim.run(o));
    ccsv << n << ',' << n * sim.tile_slot_bytes() << ',' << run.mean_error << ',' << run.mean_ssim << ',' << run.bytes << '\n';
    std::printf("| %zu | %.2f MB | %.5f | %.4f | %.2f MB |\n", n, n * sim.tile_slot_bytes() / 1e6, run.mean_error, run.mean_ssim, run.bytes / 1e6);
  }
  std::printf("\n(%zu cache runs of %d frames in %.1f s)\n", sizes.size(), frames, now_s() - t0);

  std::ofstream scsv(outdir + "/bsvtf_stream_" + label + ".csv");
  scsv << "cache_tiles,frame,bytes,ssim,error\n";
  std::printf("\nStreaming, still close grazing view, %llu bytes per frame:\n\n| cache tiles | bytes at SSIM >= 0.95 | at 0.99 | converged (SSIM 1) at |\n|---|---|---|---|\n",
              (unsigned long long)bandwidth);
  for (size_t n : {sim.tiles() / 4, sim.tiles()}) {
    TileCacheOptions o;
    o.cache_tiles = std::max<size_t>(n, 1), o.bandwidth = bandwidth, o.path.frames = frames, o.path.kind = CameraPathOptions::Kind::still;
    auto run = take(sim.run(o));
    uint64_t at95 = 0, at99 = 0, at1 = 0;
    for (const TileCacheFrame& f : run.frames) {
      scsv << o.cache_tiles << ',' << f.frame << ',' << f.bytes << ',' << f.ssim << ',' << f.error << '\n';
      if (!at95 && f.ssim >= 0.95) at95 = f.bytes;
      if (!at99 && f.ssim >= 0.99) at99 = f.bytes;
      if (!at1 && f.ssim >= 1.0) at1 = f.bytes;
    }
    auto mb = [](uint64_t b) {
      char buf[32];
      std::snprintf(buf, sizeof buf, "%.3f MB", b / 1e6);
      return b ? std::string(buf) : std::string("not reached");
    };
    std::printf("| %zu | %s | %s | %s |\n", o.cache_tiles, mb(at95).c_str(), mb(at99).c_str(), mb(at1).c_str());
  }
  return 0;
}
