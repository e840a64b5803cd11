// BSVTF (formats/bsvtf/bsvtf.h): DCT, quantisation, closed-loop parent prediction, format checks.
#include <gtest/gtest.h>
#include <omp.h>
#include <unistd.h>

#include <cstring>
#include <fstream>
#include <iterator>

#include "formats/bsvtf/bsvtf.h"
#include "formats/bsvtf/bsvtf_export.h"
#include "formats/bsvtf/tile_cache.h"
#include "core/dct.h"
#include "tests/bsvtf_fixture.h"

using namespace btfc;
using namespace bsvtf_test;

namespace {

std::vector<uint8_t> slurp(const std::string& p) {
  std::ifstream f(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(f), {}};
}

BsvtfReport write(const Model& m, const std::string& path, int quality, int tile = 64) {
  BsvtfOptions o;
  o.quality = quality, o.tile = tile;
  BsvtfReport r;
  Status s = write_bsvtf(m, o, path, &r);
  EXPECT_TRUE(s.ok()) << s.message();
  return r;
}

// Squared error and reference energy of the decoded eigen-textures of block b against the model's.
std::pair<double, double> decoded_error(const Model& m, const std::string& path, int b) {
  auto rd = BsvtfReader::open(path);
  EXPECT_TRUE(rd.ok()) << rd.status().message();
  auto dec = rd->decode_eigen_textures(b);
  EXPECT_TRUE(dec.ok()) << dec.status().message();
  const FmfBlockView v = fmf_factors(m).value().blocks[size_t(b)];
  double sse = 0, ref = 0;
  for (size_t i = 0; i < v.texels * size_t(v.C); ++i) {
    sse += (double((*dec)[i]) - v.SxV[i]) * (double((*dec)[i]) - v.SxV[i]);
    ref += double(v.SxV[i]) * v.SxV[i];
  }
  return {sse, ref};
}

}  // namespace

TEST(Bsvtf, DctRoundTripAndOrthonormality) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(-5, 5);
  float block[64], back[64];
  for (float& v : block) v = u(rng);
  double coef[64];
  dct::fdct8x8(block, 8, coef);
  double e_in = 0, e_out = 0, mean = 0;
  for (int i = 0; i < 64; ++i) e_in += double(block[i]) * block[i], e_out += coef[i] * coef[i], mean += block[i] / 64.0;
  EXPECT_NEAR(e_out, e_in, 1e-9 * e_in);  // Parseval: orthonormal
  EXPECT_NEAR(coef[0], 8 * mean, 1e-9);    // JPEG's DC scaling
  dct::idct8x8(coef, back, 8);
  for (int i = 0; i < 64; ++i) EXPECT_NEAR(back[i], block[i], 1e-5);
}

TEST(Bsvtf, QuantStepsFollowTheIjgRule) {
  const auto s50 = dct::quant_steps(50, 255.0f), s100 = dct::quant_steps(100, 2.0f), s10 = dct::quant_steps(10, 255.0f);
  for (int k = 0; k < 64; ++k) {
    EXPECT_FLOAT_EQ(s50[size_t(k)], float(dct::k_jpeg_luma[size_t(k)]));
    EXPECT_FLOAT_EQ(s100[size_t(k)], 2.0f / 255.0f);
    EXPECT_FLOAT_EQ(s10[size_t(k)], float((dct::k_jpeg_luma[size_t(k)] * 500 + 50) / 100));
  }
  for (int q = 2; q <= 100; ++q)  // finer with quality, never coarser
    EXPECT_LE(dct::quant_steps(q, 1.0f)[5], dct::quant_steps(q - 1, 1.0f)[5]);
}

TEST(Bsvtf, GeometryLevelsAndOddSizes) {
  auto g = bsvtf::Geometry::make(300, 70, 64, 4, 4).value();
  EXPECT_EQ(g.levels, 4);  // 300 -> 150 -> 75 -> 38 <= 64
  EXPECT_EQ(g.level_width(0), 38);
  EXPECT_EQ(g.level_height(0), 9);
  EXPECT_EQ(g.tiles_x(3), 5);
  EXPECT_EQ(g.tiles_y(3), 2);
  EXPECT_EQ(bsvtf::Geometry::make(1, 1, 64, 4, 4).value().levels, 1);
  EXPECT_FALSE(bsvtf::Geometry::make(64, 64, 64, 3, 4).ok());  // 70 is not a multiple of 8
  EXPECT_FALSE(bsvtf::Geometry::make(64, 64, 64, 1, 4).ok());  // border too small for the parent taps
}

TEST(Bsvtf, QualityIsMonotonicInBytesAndPsnr) {
  auto m = make_model(150, 90, 8, 0.15, 1);
  ASSERT_TRUE(m);
  const int qs[] = {20, 50, 75, 90, 100};
  BsvtfReport prev;
  for (int i = 0; i < 5; ++i) {
    const std::string p = tmp_path("q" + std::to_string(qs[i]) + ".bsvtf");
    BsvtfReport r = write(*m, p, qs[i]);
    EXPECT_EQ(r.file_bytes, std::filesystem::file_size(p));
    if (i > 0) {
      EXPECT_GT(r.tile_bytes, prev.tile_bytes) << "quality " << qs[i];
      EXPECT_GT(r.psnr, prev.psnr) << "quality " << qs[i];
    }
    // The report's error is what a reader decodes.
    auto [sse, ref] = decoded_error(*m, p, 0);
    EXPECT_NEAR(std::sqrt(sse / ref), r.rel_l2, 1e-6 + 1e-4 * r.rel_l2);
    prev = r;
  }
  // Two-sided: the quality-90 file stays near its measured numbers (41.8 dB, tiles 23:1 against
  // half floats; high because the clamped edge texels of the 3 x 2 finest tiles cost nothing).
  BsvtfReport r90 = write(*m, tmp_path("q90b.bsvtf"), 90);
  EXPECT_GE(r90.psnr, 0.75 * 41.8);
  EXPECT_LE(r90.psnr, 41.8 / 0.75);
  const double ratio = double(r90.tile_raw_half_bytes) / double(r90.tile_bytes);
  EXPECT_GE(ratio, 0.75 * 23.0);
  EXPECT_LE(ratio, 23.0 / 0.75);
}

// Every quantised coefficient is off by at most step/2, so a texel is off by at most
// sum_k |basis_k| step_k / 2 <= sum_k step_k / 8 (DCT basis values are <= 1/4) -- at every level,
// because the parent prediction is made from the decoded parent (closed loop): errors do not
// add up down the levels. At quality 100 on texel noise the coefficient errors are uniform, so
// the finest level's RMS error is step / sqrt(12) (coarser levels are smoother: below that).
static double error_bound(const BsvtfBlock& b) {
  double s = 0;
  for (float v : b.steps) s += v;
  return s / 8;
}

TEST(Bsvtf, ParentPredictionIsExactUpToQuantisation) {
  auto m = make_model(200, 136, 4, 1.0, 2);
  ASSERT_TRUE(m);
  const std::string p = tmp_path("q100.bsvtf");
  write(*m, p, 100);
  auto rd = BsvtfReader::open(p).value();
  const bsvtf::Geometry& g = rd.geometry();
  ASSERT_EQ(g.levels, 3);
  const float step = rd.blocks()[0].steps[0];
  const FmfBlockView v = fmf_factors(*m).value().blocks[0];
  // The original pyramid of texture 0.
  std::vector<std::vector<float>> lev(3);
  lev[2].resize(4 * v.texels);
  for (size_t t = 0; t < v.texels; ++t)
    for (int k = 0; k < 4; ++k) lev[2][size_t(k) * v.texels + t] = v.SxV[t * 4 + size_t(k)];
  for (int l = 2; l > 0; --l) lev[size_t(l) - 1] = bsvtf::downsample(lev[size_t(l)], g.level_width(l), g.level_height(l), 4);
  auto dec = rd.decode_texture(0).value();
  std::vector<float> truth(g.tile_floats()), one(g.tile_floats());
  for (int l = 0; l < 3; ++l) {
    double sse = 0, max_abs = 0;
    size_t n = 0;
    for (int ty = 0; ty < g.tiles_y(l); ++ty)
      for (int tx = 0; tx < g.tiles_x(l); ++tx) {
        const size_t i = size_t(ty) * size_t(g.tiles_x(l)) + size_t(tx);
        bsvtf::extract_tile(g, lev[size_t(l)].data(), g.level_width(l), g.level_height(l), tx, ty, truth.data());
        const float* d = &dec[size_t(l)][i * g.tile_floats()];
        for (size_t j = 0; j < truth.size(); ++j) {
          const double e = double(d[j]) - truth[j];
          sse += e * e, max_abs = std::max(max_abs, std::abs(e)), ++n;
        }
        // One tile decoded on its own from its decoded parent equals the full decode.
        const float* parent = l == 0 ? nullptr : &dec[size_t(l) - 1][(size_t(ty / 2) * size_t(g.tiles_x(l - 1)) + size_t(tx / 2)) * g.tile_floats()];
        ASSERT_TRUE(rd.read_tile(0, l, tx, ty, parent, one.data()).ok());
        EXPECT_EQ(0, std::memcmp(one.data(), d, one.size() * sizeof(float)));
      }
    const double rms = std::sqrt(sse / double(n)), expect = step / std::sqrt(12.0);
    EXPECT_LE(max_abs, error_bound(rd.blocks()[0])) << "level " << l;
    EXPECT_GT(max_abs, 0.1 * error_bound(rd.blocks()[0])) << "level " << l;
    if (l == 2) {
      EXPECT_GE(rms, 0.75 * expect);
    }
    EXPECT_LE(rms, expect / 0.75) << "level " << l;
  }
}

TEST(Bsvtf, TinyAndOddTextures) {
  for (auto [w, h] : {std::pair{1, 1}, std::pair{65, 1}, std::pair{1, 130}, std::pair{67, 129}}) {
    auto m = make_model(w, h, 5, 0.05, 4);
    ASSERT_TRUE(m);
    const std::string p = tmp_path("odd.bsvtf");
    BsvtfReport r = write(*m, p, 95);
    auto rd = BsvtfReader::open(p).value();
    EXPECT_LE(r.max_abs, error_bound(rd.blocks()[0])) << w << "x" << h;
    EXPECT_GT(r.max_abs, 0) << w << "x" << h;
    auto [sse, ref] = decoded_error(*m, p, 0);
    EXPECT_NEAR(std::sqrt(sse / ref), r.rel_l2, 1e-6 + 1e-4 * r.rel_l2);
    EXPECT_EQ(r.textures, 2u);  // 5 components -> groups of 4 + 1
    auto U = rd.decode_eigen_abrdfs(0).value();
    const FmfBlockView v = fmf_factors(*m).value().blocks[0];
    for (size_t i = 0; i < U.size(); ++i) EXPECT_NEAR(U[i], v.U[i], 1e-3);  // half packets
  }
}

TEST(Bsvtf, DfmfBlocks) {
  auto m = make_model(70, 40, 6, 0.1, 5, 11);
  ASSERT_TRUE(m);
  const std::string p = tmp_path("dfmf.bsvtf");
  BsvtfReport r = write(*m, p, 90);
  EXPECT_EQ(r.block_psnr.size(), 3u);
  auto rd = BsvtfReader::open(p).value();
  EXPECT_EQ(rd.color_model(), 11);
  EXPECT_EQ(rd.textures(), 2u + 1 + 1);
  for (int b = 0; b < 3; ++b) {
    const FmfBlockView v = fmf_factors(*m).value().blocks[size_t(b)];
    auto dec = rd.decode_eigen_textures(b).value();
    double max_abs = 0;
    for (size_t i = 0; i < dec.size(); ++i) max_abs = std::max(max_abs, std::abs(double(dec[i]) - v.SxV[i]));
    EXPECT_LE(max_abs, error_bound(rd.blocks()[size_t(b)])) << "block " << b;
    EXPECT_GT(max_abs, 0.05 * error_bound(rd.blocks()[size_t(b)])) << "block " << b;
  }
}

// RGB of texel i at row r (= light + lights x view) from decoded dfmf blocks (Y', U', V'
// factors, texels x C and rows x C each), by bsvtf.h's evaluation with luminance offset e.
static std::array<double, 3> dfmf_rgb(const std::vector<std::vector<float>>& tex, const std::vector<std::vector<float>>& abrdf,
                                      const std::vector<uint32_t>& C, size_t i, size_t r, double e) {
  double yuv[3];
  for (int b = 0; b < 3; ++b) {
    yuv[b] = 0;
    for (uint32_t c = 0; c < C[size_t(b)]; ++c) yuv[b] += double(abrdf[size_t(b)][r * C[size_t(b)] + c]) * tex[size_t(b)][i * C[size_t(b)] + c];
  }
  const double y = std::exp(yuv[0]) - e, u = yuv[1] * (y + e), v = yuv[2] * (y + e);
  return {y + 1.13983 * v, y - 0.39465 * u - 0.5806 * v, y + 2.03211 * u};
}

TEST(Bsvtf, DfmfWithItsOwnOffsetIsColourModel13) {
  // btfc's dfmf encodes pick the luminance offset from the data: such a model is written as
  // colour model 13 (version 1.1) with its offset; Bonn's 1e-5 stays model 11 in a 1.0 file.
  const float offset = 0.25f;
  auto m = make_model(70, 40, 6, 0.1, 5, 11, {}, offset);
  auto m11 = make_model(70, 40, 6, 0.1, 5, 11);
  ASSERT_TRUE(m && m11);
  const std::string p = tmp_path("dfmf13.bsvtf"), p11 = tmp_path("dfmf11.bsvtf");
  write(*m, p, 95);
  write(*m11, p11, 95);
  auto rd = BsvtfReader::open(p).value();
  auto rd11 = BsvtfReader::open(p11).value();
  EXPECT_EQ(rd.color_model(), 13);
  EXPECT_EQ(rd.luminance_offset(), offset);
  EXPECT_EQ(rd11.color_model(), 11);
  EXPECT_EQ(rd11.luminance_offset(), 1e-5f);
  const std::vector<uint8_t> b13 = slurp(p), b11 = slurp(p11);
  ASSERT_GT(b11.size(), 12u);
  EXPECT_EQ(b13[10], 1);  // minor version
  EXPECT_EQ(b11[10], 0);
  EXPECT_EQ(rd.header_bytes(), rd11.header_bytes() + 4);  // the offset; the same factors otherwise
  // The file evaluates to the model: decoded factors through the formula with the stored offset
  // agree with Model::eval; with Bonn's offset instead they would not.
  std::vector<std::vector<float>> tex(3), abrdf(3);
  std::vector<uint32_t> C(3);
  for (int b = 0; b < 3; ++b) {
    tex[size_t(b)] = rd.decode_eigen_textures(b).value();
    abrdf[size_t(b)] = rd.decode_eigen_abrdfs(b).value();
    C[size_t(b)] = rd.blocks()[size_t(b)].components;
  }
  // The model's own factors through the same formula: the model's values (float rounding).
  std::vector<std::vector<float>> mtex(3), mabrdf(3);
  const FmfFactorsView fv = fmf_factors(*m).value();
  for (size_t b = 0; b < 3; ++b) {
    mtex[b].assign(fv.blocks[b].SxV, fv.blocks[b].SxV + fv.blocks[b].texels * size_t(fv.blocks[b].C));
    mabrdf[b].assign(fv.blocks[b].U, fv.blocks[b].U + fv.blocks[b].rows * size_t(fv.blocks[b].C));
  }
  const BtfDesc& d = m->desc();
  double err = 0, err_bonn = 0, err_exact = 0, ref = 0;
  for (int y = 0; y < d.height; y += 7)
    for (int x = 0; x < d.width; x += 5)
      for (int v = 0; v < int(d.num_views()); ++v)
        for (int l = 0; l < int(d.num_lights()); ++l) {
          float want[3];
          m->eval(x, y, l, v, want);
          const size_t i = size_t(y) * size_t(d.width) + size_t(x), r = size_t(l) + size_t(d.num_lights()) * size_t(v);
          const auto got = dfmf_rgb(tex, abrdf, C, i, r, rd.luminance_offset()), bonn = dfmf_rgb(tex, abrdf, C, i, r, 1e-5);
          const auto exact = dfmf_rgb(mtex, mabrdf, C, i, r, rd.luminance_offset());
          for (int c = 0; c < 3; ++c) err_exact += (exact[size_t(c)] - want[c]) * (exact[size_t(c)] - want[c]);
          for (int c = 0; c < 3; ++c)
            err += (got[size_t(c)] - want[c]) * (got[size_t(c)] - want[c]), err_bonn += (bonn[size_t(c)] - want[c]) * (bonn[size_t(c)] - want[c]),
                ref += double(want[c]) * want[c];
        }
  ASSERT_GT(ref, 0);
  std::printf("dfmf model 13: rel. error exact %.3g, file %.3g, file with offset 1e-5 %.3g\n", std::sqrt(err_exact / ref), std::sqrt(err / ref),
              std::sqrt(err_bonn / ref));
  EXPECT_LT(std::sqrt(err_exact / ref), 1e-5);
  // Quality 95 tiles of noisy eigen-textures and half packets, through exp: 0.025 measured.
  EXPECT_LE(std::sqrt(err / ref), 0.032);
  EXPECT_GE(std::sqrt(err / ref), 0.75 * 0.032);
  EXPECT_GT(std::sqrt(err_bonn / ref), 3 * std::sqrt(err / ref));  // 0.107 measured
  // The tile cache reads model 13: a small cache's run on the file completes with finite
  // statistics. (That it shades with the stored offset: tile_cache_test.cpp,
  // ConvergedImageIsTheModelShadedWithTheFilesOffset.)
  auto sim = TileCacheSim::make(rd);
  ASSERT_TRUE(sim.ok()) << sim.status().message();
  TileCacheOptions o;
  o.cache_tiles = 2, o.path.frames = 4, o.path.width = 48, o.path.height = 36;
  auto run = sim->run(o);
  ASSERT_TRUE(run.ok()) << run.status().message();
  EXPECT_TRUE(std::isfinite(run->mean_error) && std::isfinite(run->mean_ssim));
  EXPECT_LE(run->mean_ssim, 1.0);
}

TEST(Bsvtf, ExportsAttachTheStreamingFileOfEveryRgbAndDfmfModel) {
  // `btfc export` (attach_bsvtf): rgb and dfmf of any offset get model.bsvtf; a factorization
  // read from a Bonn file in another colour model (YCoCg, 4) exports without it, with a warning,
  // and write_bsvtf refuses it as unsupported.
  for (auto [color, offset, attached] : {std::tuple{0, 1e-5f, true}, std::tuple{11, 1e-5f, true}, std::tuple{11, 3.5f, true},
                                         std::tuple{4, 1e-5f, false}}) {
    auto m = make_model(20, 12, 4, 0.1, 8, color, {}, offset);
    ASSERT_TRUE(m) << color;
    gpu::ExportBundle bundle;
    EXPECT_EQ(attach_bsvtf(bundle, *m, gpu::ExportOptions{}, BsvtfOptions{}, nullptr), attached) << color << " " << offset;
    EXPECT_EQ(bool(bundle.write_extra), attached);
    if (attached) {
      EXPECT_TRUE(bundle.warnings.empty()) << bundle.warnings[0];
    } else {
      ASSERT_EQ(bundle.warnings.size(), 1u);
      EXPECT_NE(bundle.warnings[0].find("colour models 0 and 11), this model's is 4"), std::string::npos) << bundle.warnings[0];
      EXPECT_EQ(write_bsvtf(*m, BsvtfOptions{}, tmp_path("ycocg.bsvtf"), nullptr).code(), StatusCode::unsupported);
      EXPECT_FALSE(std::filesystem::exists(tmp_path("ycocg.bsvtf")));
    }
  }
}

TEST(Bsvtf, WeightsFollowEquation8) {
  // Finest level: a +-a checkerboard on top of a constant c. Its 2x2 average is exactly c, so
  // w(finest) = a^2 (one real plane), and every coarser level is constant: w = 0 there,
  // w(level 0) = its mean square c^2.
  const int w = 130, h = 66;
  const float a = 0.5f, c = 3.0f;
  std::vector<float> tex(size_t(w) * h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) tex[size_t(y) * w + size_t(x)] = c + ((x + y) % 2 ? a : -a);
  auto m = make_model(w, h, 1, 0, 6, 0, tex);
  ASSERT_TRUE(m);
  const std::string p = tmp_path("w.bsvtf");
  write(*m, p, 90);
  auto rd = BsvtfReader::open(p).value();
  const bsvtf::Geometry& g = rd.geometry();
  for (const BsvtfEntry& e : rd.entries()) {
    if (e.kind != BsvtfEntry::tile) continue;
    const double expect = e.level == g.finest() ? a * a : e.level == 0 ? c * c : 0.0;
    // Interior tiles only: edge tiles hold clamped texels outside the texture.
    if (int(e.tx + 1) * g.tile <= g.level_width(e.level) && int(e.ty + 1) * g.tile <= g.level_height(e.level)) {
      EXPECT_NEAR(e.weight, expect, 1e-4) << "level " << int(e.level);
    }
  }
  // A linear ramp: the bilinear up-sampling of its 2 x 2 box average is the ramp again, so
  // tiles away from the edges have w = 0 (nearest-neighbour up-sampling would give 1.25e-4).
  const int rw = 260, rh = 200;
  std::vector<float> ramp(size_t(rw) * rh);
  for (int y = 0; y < rh; ++y)
    for (int x = 0; x < rw; ++x) ramp[size_t(y) * rw + size_t(x)] = 0.01f * x + 0.02f * y;
  auto mr = make_model(rw, rh, 1, 0, 6, 0, ramp);
  write(*mr, p, 90);
  auto rr = BsvtfReader::open(p).value();
  const bsvtf::Geometry& gr = rr.geometry();
  int checked = 0;
  for (const BsvtfEntry& e : rr.entries())
    if (e.kind == BsvtfEntry::tile && e.level == gr.finest() && e.tx > 0 && e.ty > 0 && int(e.tx) + 1 < gr.tiles_x(e.level) &&
        int(e.ty) + 1 < gr.tiles_y(e.level)) {
      EXPECT_LT(e.weight, 1e-8) << e.tx << "," << e.ty;
      ++checked;
    }
  EXPECT_EQ(checked, 6);
}

TEST(Bsvtf, DeterministicAcrossThreadCounts) {
  auto m = make_model(150, 100, 8, 0.2, 7);
  const std::string a = tmp_path("det1.bsvtf"), b = tmp_path("det2.bsvtf");
  const int threads = omp_get_max_threads();
  omp_set_num_threads(1);
  write(*m, a, 80);
  omp_set_num_threads(std::max(2, threads));
  write(*m, b, 80);
  omp_set_num_threads(threads);
  EXPECT_EQ(slurp(a), slurp(b));
}

TEST(Bsvtf, RefusesWhatItCannotStore) {
  auto m12 = make_model(8, 8, 2, 0, 8, 12);  // Bonn FMF with dynamic range reduction
  ASSERT_TRUE(m12);
  const std::string p = tmp_path("never.bsvtf");
  Status s = write_bsvtf(*m12, {}, p, nullptr);
  EXPECT_EQ(s.code(), StatusCode::unsupported);
  EXPECT_NE(s.message().find("colour model 12"), std::string::npos) << s.message();
  auto m = make_model(8, 8, 2, 0, 8);
  BsvtfOptions bad;
  bad.quality = 0;
  EXPECT_EQ(write_bsvtf(*m, bad, p, nullptr).code(), StatusCode::invalid_argument);
  bad.quality = 50, bad.tile = 60;  // 68 is not a multiple of 8
  EXPECT_EQ(write_bsvtf(*m, bad, p, nullptr).code(), StatusCode::invalid_argument);
  EXPECT_FALSE(std::filesystem::exists(p));
  // Unwritable directory: io_error, and no temporary left behind.
  s = write_bsvtf(*m, {}, "/nonexistent-dir/x.bsvtf", nullptr);
  EXPECT_EQ(s.code(), StatusCode::io_error);
  EXPECT_NE(s.message().find("/nonexistent-dir/x.bsvtf"), std::string::npos);
}
