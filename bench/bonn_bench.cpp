// Bonn DFMF read + decode throughput (issue 3; docs/benchmarks.md).
//
// Generates a DFMF file of UBO2014 shape (Dome 1: 151 x 151 directions, 400 x 400 texels,
// 100 components per channel, colour model 11, half scalars; ~110 MB), then times
//   write  - write_bonn_dfmf (half conversion + file write)
//   read   - open_bonn_model (parse, half -> float, factors into the fmf model)
//   decode - full decode in texel blocks of `--lines` scan lines (every direction), each block
//            decoded into a reused Btf and discarded: 400*400*151*151*3 = 10.9 G values (44 GB
//            float) never exist at once.
// and reports values/s and the output bandwidth (4 bytes per value) against the 77 GB/s
// two-thread STREAM bound (../shared/spec/toolchain.md 4a).
//
//   bench_bonn [--width 400] [--height 400] [--rank 100] [--lines 4] [--blocks N (0 = all)]
//              [--file /tmp/bench_ubo2014.btf] [--keep]
#include <cmath>
#include <cstdio>
#include <cstring>
#include <random>
#include <string>

#include "bench/bench_timing.h"
#include "codecs/fmf/fmf.h"
#include "core/cl_runtime.h"
#include "formats/bonn/bonn_btf.h"

using namespace btfc;

using btfc::bench::now_s;

int main(int argc, char** argv) {
  int width = 400, height = 400, rank = 100, lines = 4, blocks = 0;
  bool keep = false;
  std::string path = "/tmp/bench_ubo2014.btf";
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() { return i + 1 < argc ? std::string(argv[++i]) : std::string(); };
    if (a == "--width") width = std::stoi(next());
    else if (a == "--height") height = std::stoi(next());
    else if (a == "--rank") rank = std::stoi(next());
    else if (a == "--lines") lines = std::stoi(next());
    else if (a == "--blocks") blocks = std::stoi(next());
    else if (a == "--file") path = next();
    else if (a == "--keep") keep = true;
    else {
      std::fprintf(stderr, "unknown option %s\n", a.c_str());
      return 1;
    }
  }
  BtfDesc d;
  d.width = width, d.height = height, d.channels = 3;
  d.lights = DirectionSet::ubo2014();
  d.views = DirectionSet::ubo2014();
  const size_t rows = d.num_images(), texels = d.num_texels();

  // Factors shaped like a real decorrelated factorization: orthonormal-ish U columns (entries
  // ~ 1/sqrt(rows)) and SxV decaying with the component, so exp() of log-luminance stays sane.
  std::mt19937 rng(1);
  std::normal_distribution<float> g(0, 1);
  std::vector<FmfFactors> f(3);
  const char* names[3] = {"y", "u", "v"};
  for (int c = 0; c < 3; ++c) {
    f[c].name = names[c];
    f[c].C = rank;
    f[c].S.resize(size_t(rank));
    f[c].U.resize(rows * size_t(rank));
    f[c].SxV.resize(texels * size_t(rank));
    for (int k = 0; k < rank; ++k) f[c].S[size_t(k)] = 100.0f / float(k + 1);
    const float su = 1.0f / std::sqrt(float(rows));
    for (float& x : f[c].U) x = su * g(rng);
    for (size_t t = 0; t < texels; ++t)
      for (int k = 0; k < rank; ++k) f[c].SxV[t * size_t(rank) + size_t(k)] = (c == 0 ? 20.0f : 2.0f) * g(rng) / float(k + 1);
  }
  const float mean[3] = {0, 0, 0}, T[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  auto made = make_fmf_model(d, 11, std::move(f), mean, T, true);
  if (!made.ok()) return std::fprintf(stderr, "%s\n", made.status().message().c_str()), 1;

  double t0 = now_s();
  Status s = write_bonn_dfmf(**made, path, true);
  const double t_write = now_s() - t0;
  if (!s.ok()) return std::fprintf(stderr, "%s\n", s.message().c_str()), 1;
  made = Status();  // free the generator's model before reading

  t0 = now_s();
  BonnInfo info;
  auto model = open_bonn_model(path, &info);
  const double t_read = now_s() - t0;
  if (!model.ok()) return std::fprintf(stderr, "%s\n", model.status().message().c_str()), 1;
  const double file_mb = double(info.file_size) / 1e6;

  std::string why;
  const bool cl = ocl::use_opencl(&why);
  const int nblocks_all = (height + lines - 1) / lines;
  const int nblocks = blocks > 0 ? std::min(blocks, nblocks_all) : nblocks_all;
  Btf out;
  double values = 0;
  t0 = now_s();
  for (int b = 0; b < nblocks; ++b) {
    DecodeRequest req;
    req.y0 = b * lines;
    req.height = std::min(lines, height - req.y0);
    s = (*model)->decode(req, out);
    if (!s.ok()) return std::fprintf(stderr, "%s\n", s.message().c_str()), 1;
    values += double(out.size());
  }
  const double t_dec = now_s() - t0;
  const double full_values = double(d.num_values());

  std::printf("DFMF %dx%d texels, 151x151 directions, %d components/channel, half: file %.1f MB, dome1=%s\n", width, height, rank,
              file_mb, info.dome1 ? "yes" : "no");
  std::printf("write  %.2f s  (%.0f MB/s)\n", t_write, file_mb / t_write);
  std::printf("read   %.2f s  (%.0f MB/s of file, half -> float factors)\n", t_read, file_mb / t_read);
  std::printf("decode %.2f s for %.3g values (%d of %d blocks of %d lines; device %s)\n", t_dec, values, nblocks, nblocks_all, lines,
              cl ? "OpenCL" : ("CPU" + (why.empty() ? std::string() : " - " + why)).c_str());
  std::printf("       %.3g values/s = %.2f GB/s of float output (%.1f %% of the 77 GB/s STREAM bound)\n", values / t_dec,
              4 * values / t_dec / 1e9, 100 * 4 * values / t_dec / 1e9 / 77.0);
  std::printf("       full decode (%.3g values) extrapolated: %.1f s; read + full decode: %.1f s\n", full_values,
              full_values / (values / t_dec), t_read + full_values / (values / t_dec));
  if (!keep) std::remove(path.c_str());
  return 0;
}
