// Tests of the lpyr GPU exporter (codecs/lpyr/lpyr_export.cpp) and of what every codec exporter
// shares: the CPU emulation of the shader, reading only the exported texture values, against the
// model's own evaluation (measured directions, Delaunay-interpolated directions at direction-map
// cell centres, levels of detail, the paper's nearest-direction renderer), with the half-float
// error two-sided; HDR scaling / clamping; KTX2 round trips; GLSL ES 3.00 syntax through
// glslangValidator when it is installed. lpca: export_lpca_test.cpp.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <random>

#include "codecs/lpca/lpca.h"
#include "codecs/lpyr/lpyr.h"
#include "codecs/lpyr/lpyr_export.h"
#include "codecs/lpyr/lpyr_internal.h"
#include "formats/gpu/ktx2.h"
#include "tests/export_test_util.h"

using namespace btfc;
using namespace btfc::gpu;
using namespace btfc::export_test;

namespace {

// ---- lpyr ----

// Worst-case error of a half export at measured (l, v), lod 0, from the float export's values:
// every stored value (means, weights / scale, eigen entries) rounded once to half.
double lpyr_half_bound(const ExportBundle& f, int x, int y, int l, int v) {
  const nlohmann::json& e = f.evaluation;
  const int nl = e["lights"], nv = e["views"];
  const GpuTexture &D = *f.find("weight_map"), &E = *f.find("eigen_map"), &M = *f.find("mean_map");
  double ycc[3] = {0, 0, 0};
  for (int k = 0; k <= e["lmax"].get<int>(); ++k) {
    const nlohmann::json& lv = e["levels"][size_t(k)];
    const int w = lv["size"][0], h = lv["size"][1], ox = lv["weight_offset"][0], oy = lv["weight_offset"][1];
    const int dx[3] = {ox, ox + w, ox}, dy[3] = {oy, oy, oy + h};
    for (int c = 0; c < 3; ++c) ycc[c] += std::abs(M.f[0][((size_t(k) * size_t(nv) + size_t(v)) * size_t(nl) + size_t(l)) * 4 + size_t(c)]) * k_half_rel + k_half_abs;
    for (int j = 0; j < 3; ++j)
      for (int q = 0; q < 4; ++q) {
        const double dv = D.f[0][((size_t(dy[j] + (y >> k))) * D.width + size_t(dx[j] + (x >> k))) * 4 + size_t(q)] * lv["weight_scale"][size_t(j)][size_t(q)].get<double>();
        const double ev = E.f[0][((size_t(k) * size_t(nv) + size_t(v)) * E.width + size_t(j * nl + l)) * 4 + size_t(q)];
        ycc[j < 2 ? 0 : 1 + q / 2] += std::abs(dv * ev) * 2.01 * k_half_rel + k_half_abs * (std::abs(dv) + std::abs(ev));
      }
  }
  double rgb = 0;  // the largest channel's bound through the YCbCr -> RGB matrix
  for (int i = 0; i < 3; ++i) {
    double s = 0;
    for (int c = 0; c < 3; ++c) s += std::abs(e["ycbcr_to_rgb"][size_t(i)][size_t(c)].get<double>()) * ycc[c];
    rgb = std::max(rgb, s);
  }
  return rgb;
}

TEST(LpyrExport, MeasuredDirectionsMatchModelHalfTwoSidedFloatExact) {
  for (auto [w, h] : {std::pair{13, 9}, std::pair{5, 3}}) {
    Btf btf = synth(w, h);
    for (const char* spec : {"lpyr:mean=phong", "lpyr:mean=stored:precision=float:y=5:c=1"}) {
      auto m = encode(lpyr_codec(), btf, spec);
      ASSERT_TRUE(m);
      const ExportBundle bh = bundle(*m, true), bf = bundle(*m, false);
      const BtfDesc& d = m->desc();
      Errors eh, ef;
      for (int y = 0; y < d.height; ++y)
        for (int x = 0; x < d.width; ++x)
          for (int l = 0; l < int(d.num_lights()); l += 5)
            for (int v = 0; v < int(d.num_views()); ++v) {
              ShaderQuery q = at_texel(d, x, y);
              q.light = l, q.view = v;
              float ref[3], gh[3], gf[3];
              m->eval(x, y, l, v, ref);
              find_exporter("lpyr")->emulate(bh, q, gh);
              find_exporter("lpyr")->emulate(bf, q, gf);
              const double bound = lpyr_half_bound(bf, x, y, l, v) + float_tol(ref);
              for (int c = 0; c < 3; ++c) {
                const double e1 = std::abs(gh[c] - ref[c]), e2 = std::abs(gf[c] - ref[c]);
                eh.max_err = std::max(eh.max_err, e1), eh.max_ratio = std::max(eh.max_ratio, e1 / bound);
                eh.within &= e1 <= bound;
                ef.max_err = std::max(ef.max_err, e2), ef.within &= e2 <= float_tol(ref);
              }
            }
      std::printf("lpyr %dx%d %s: half max |err| %.3g (max err/bound %.3f), float max |err| %.3g\n", w, h, spec, eh.max_err, eh.max_ratio, ef.max_err);
      EXPECT_TRUE(eh.within) << spec;
      EXPECT_GT(eh.max_ratio, 0.1) << spec;  // the means are not half values: the loss shows
      EXPECT_TRUE(ef.within) << spec << " float export max err " << ef.max_err;
    }
  }
}

TEST(LpyrExport, ArbitraryDirectionsMatchEvalDirAtCellCentresAndLodMatchesEvalLod) {
  Btf btf = synth(13, 9);
  auto m = encode(lpyr_codec(), btf, "lpyr:mean=phong");
  ASSERT_TRUE(m);
  const auto* lm = dynamic_cast<const lpyr::LpyrModel*>(m.get());
  ASSERT_GT(lm->lmax(), 1);
  const ExportBundle bf = bundle(*m, false, 48);
  const BtfDesc& d = m->desc();
  const std::vector<Vec3> dl = random_cell_centres(48, 12, 1), dv = random_cell_centres(48, 12, 2);
  double max_err = 0;
  for (int y = 0; y < d.height; y += 2)
    for (int x = 0; x < d.width; x += 3)
      for (size_t i = 0; i < dl.size(); ++i) {
        ShaderQuery q = at_texel(d, x, y);
        q.wl = dl[i], q.wv = dv[(i * 5) % dv.size()];
        float ref[3], g[3];
        ASSERT_TRUE(m->eval_dir(x, y, q.wl, q.wv, ref).ok());
        find_exporter("lpyr")->emulate(bf, q, g);
        for (int c = 0; c < 3; ++c) {
          max_err = std::max(max_err, double(std::abs(g[c] - ref[c])));
          EXPECT_LE(std::abs(g[c] - ref[c]), float_tol(ref)) << x << " " << y << " " << i;
        }
      }
  std::printf("lpyr eval_dir at cell centres, float export: max |err| %.3g\n", max_err);
  // Levels of detail, measured directions: btf_eval_measured_lod == eval_lod.
  for (float lod : {0.25f, 1.0f, 1.5f, float(lm->lmax()) - 0.3f, float(lm->lmax())})
    for (int y = 0; y < d.height; ++y)
      for (int x = 0; x < d.width; ++x) {
        ShaderQuery q = at_texel(d, x, y);
        q.light = (x * 7 + y) % int(d.num_lights()), q.view = (x + y) % int(d.num_views());
        float ref[3], g[3];
        ASSERT_TRUE(m->eval_lod(x, y, q.light, q.view, lod, ref).ok());
        lpyr_emulate(bf, q, lod, LpyrRenderer::delaunay, g);
        for (int c = 0; c < 3; ++c) EXPECT_LE(std::abs(g[c] - ref[c]), float_tol(ref)) << "lod " << lod;
      }
}

// The paper's renderer: nearest measured directions (LUT of the query's cell centre) and the
// Phong top mean at the actual directions.
TEST(LpyrExport, NearestRendererUsesLutAndAnalyticPhong) {
  Btf btf = synth(9, 7);
  for (const char* spec : {"lpyr:mean=phong", "lpyr:mean=stored"}) {
    auto m = encode(lpyr_codec(), btf, spec);
    ASSERT_TRUE(m);
    const auto* lm = dynamic_cast<const lpyr::LpyrModel*>(m.get());
    const ExportBundle bf = bundle(*m, false);
    const BtfDesc& d = m->desc();
    EXPECT_EQ(bf.find("phong") != nullptr, lm->uses_phong());
    auto nearest = [](const DirectionSet& s, const Vec3& q) {
      int cx, cy;
      Vec3 c;
      direction_cell(q, 32, cx, cy);
      const double px = (cx + 0.5) / 16 - 1, py = (cy + 0.5) / 16 - 1, r2 = std::min(1.0, px * px + py * py), n = std::sqrt(px * px + py * py);
      const double sx = n > 1 ? px / n : px, sy = n > 1 ? py / n : py;
      c = {float(2 * sx / (1 + r2)), float(2 * sy / (1 + r2)), float((1 - r2) / (1 + r2))};
      int best = 0;
      for (size_t i = 0; i < s.size(); ++i)
        if (s.dirs[i].x * c.x + s.dirs[i].y * c.y + s.dirs[i].z * c.z > s.dirs[size_t(best)].x * c.x + s.dirs[size_t(best)].y * c.y + s.dirs[size_t(best)].z * c.z) best = int(i);
      return best;
    };
    std::mt19937 rng(3);
    std::uniform_real_distribution<double> th(0, 1.3), ph(0, 6.283);
    for (int i = 0; i < 60; ++i) {
      ShaderQuery q = at_texel(d, i % d.width, (i / 3) % d.height);
      q.wl = dir_from_theta_phi(th(rng), ph(rng)), q.wv = dir_from_theta_phi(th(rng), ph(rng));
      const int l = nearest(d.lights, q.wl), v = nearest(d.views, q.wv);
      const float lod = float(i % 5) * 0.5f;
      float ref[3], g[3];
      ASSERT_TRUE(m->eval_lod(i % d.width, (i / 3) % d.height, l, v, std::min<double>(lod, lm->lmax()), ref).ok());
      if (lm->uses_phong()) {  // Y moves every channel alike (the first column of YCbCr -> RGB is 1)
        const double dy = lpyr::phong_eval(lm->phong(), q.wl, q.wv) - lpyr::phong_eval(lm->phong(), d.lights.dirs[size_t(l)], d.views.dirs[size_t(v)]);
        for (float& r : ref) r += float(dy);
      }
      lpyr_emulate(bf, q, lod, LpyrRenderer::nearest, g);
      for (int c = 0; c < 3; ++c) EXPECT_NEAR(g[c], ref[c], 1e-5 * (1 + std::abs(ref[c]))) << spec << " query " << i;
    }
  }
}

TEST(LpyrExport, UnsupportedLayoutSaysWhy) {
  auto m = encode(lpyr_codec(), synth(8, 8), "lpyr:y=9");
  ASSERT_TRUE(m);
  auto b = build_export(*m, ExportOptions{});
  ASSERT_FALSE(b.ok());
  EXPECT_EQ(b.status().code(), StatusCode::unsupported);
  EXPECT_NE(b.status().message().find("at most 8 Y"), std::string::npos) << b.status().message();
}

// ---- both ----

// HDR data (values ~1e6, beyond half's 65504): scaled by powers of two, never clamped, unless
// --clamp-half asks for clamping (then counted and reported). lpca stores only normalized values.
TEST(CodecExport, HdrHalfExportScalesOrClampsAndReports) {
  SynthOptions so;
  so.width = 7, so.height = 5, so.views = some_views(), so.scale = 1e6f;
  const Btf btf = synthesize_btf(so).value();
  for (auto [codec, spec] : {std::pair{&lpyr_codec(), "lpyr:mean=stored"}, std::pair{&lpca_codec(), "lpca:clusters=2:components=3"}}) {
    auto m = encode(*codec, btf, spec);
    ASSERT_TRUE(m);
    const ExportBundle b = bundle(*m, true);
    EXPECT_EQ(b.clamped(), 0u) << spec;
    EXPECT_TRUE(b.warnings.empty()) << spec;
    double max_rel = 0;
    for (int i = 0; i < 200; ++i) {
      ShaderQuery q = at_texel(m->desc(), i % 7, i % 5);
      q.light = (i * 13) % 81, q.view = i % 8;
      float ref[3], g[3];
      m->eval(i % 7, i % 5, q.light, q.view, ref);
      find_exporter(b.codec)->emulate(b, q, g);
      for (int c = 0; c < 3; ++c) max_rel = std::max(max_rel, std::abs(g[c] - ref[c]) / 1e6);
    }
    std::printf("%s HDR x1e6 half export: max |err| / 1e6 = %.3g\n", spec, max_rel);
    EXPECT_LT(max_rel, 2e-3) << spec;  // half rounding of values up to ~1e6 (relative 2^-11 per value)
    ExportOptions o;
    o.clamp_half = true;
    const ExportBundle c = build_export(*m, o).value();
    if (b.codec == "lpyr") {
      EXPECT_GT(c.clamped(), 0u);
      ASSERT_FALSE(c.warnings.empty());
      EXPECT_NE(c.warnings.back().find("clamped"), std::string::npos);
    } else {
      EXPECT_EQ(c.clamped(), 0u);
    }
  }
}

std::vector<ExportBundle> all_bundles() {
  std::vector<ExportBundle> out;
  Btf btf = synth(7, 5);
  for (const char* spec : {"lpyr:mean=phong", "lpyr:mean=stored:precision=float"}) out.push_back(bundle(*encode(lpyr_codec(), btf, spec), true));
  auto m = encode(lpca_codec(), btf, "lpca:clusters=2:components=6");
  out.push_back(bundle(*m, false));
  EnvironmentSH env;
  env.order = 3;
  env.coeffs.assign(27, 0.0);
  env.coeffs[0] = env.coeffs[9] = env.coeffs[18] = 1.0;
  EXPECT_TRUE(attach_environment(*m, env).ok());
  out.push_back(bundle(*m, true));
  return out;
}

TEST(CodecExport, Ktx2RoundTripAndSamplersDeclared) {
  const std::string dir = ::testing::TempDir();
  for (const ExportBundle& b : all_bundles())
    for (const GpuTexture& t : b.textures) {
      EXPECT_NE(b.glsl.find("u_" + t.name + ";"), std::string::npos) << b.codec << " " << t.name;
      const std::string path = dir + "/" + b.codec + "_" + t.name + "_" + std::to_string(::getpid()) + ".ktx2";
      ASSERT_TRUE(write_ktx2(t, path).ok());
      auto r = read_ktx2(path);
      std::remove(path.c_str());
      ASSERT_TRUE(r.ok()) << r.status().message();
      EXPECT_EQ(r->format, t.format);
      EXPECT_EQ(r->width, t.width);
      EXPECT_EQ(r->height, t.height);
      EXPECT_EQ(r->layers, t.layers);
      EXPECT_EQ(r->f, t.f) << b.codec << " " << t.name;
      EXPECT_EQ(r->u, t.u) << b.codec << " " << t.name;
    }
}

TEST(CodecExport, GlslCompilesWithGlslangValidator) {
  if (std::system("command -v glslangValidator > /dev/null 2>&1") != 0) GTEST_SKIP() << "glslangValidator not installed";
  int n = 0;
  for (const ExportBundle& b : all_bundles()) {
    EXPECT_EQ(b.glsl.rfind("#version 300 es\n", 0), 0u) << b.codec;
    // As written (with main) and as a harness includes it (BTFC_NO_MAIN after the #version line).
    const size_t eol = b.glsl.find('\n') + 1;
    for (const std::string& src : {b.glsl, b.glsl.substr(0, eol) + "#define BTFC_NO_MAIN\n" + b.glsl.substr(eol)}) {
      const std::string path = ::testing::TempDir() + "/btfc_" + b.codec + std::to_string(n++) + "_" + std::to_string(::getpid()) + ".frag";
      std::ofstream(path) << src;
      const int rc = std::system(("glslangValidator -S frag " + path + " > " + path + ".log 2>&1").c_str());
      std::ifstream log(path + ".log");
      const std::string text((std::istreambuf_iterator<char>(log)), std::istreambuf_iterator<char>());
      EXPECT_EQ(rc, 0) << b.codec << ":\n" << text << "\n" << src;
      std::remove(path.c_str());
      std::remove((path + ".log").c_str());
    }
  }
}

}  // namespace
