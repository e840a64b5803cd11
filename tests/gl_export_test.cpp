// The real-GPU-API check of the exports (issue 8): every codec that has an exporter is encoded
// from a small synthetic BTF, exported to a directory, and its btf.frag is run through OpenGL ES
// on Mesa's llvmpipe (tests/gl/egl_runner.h) at a grid of (texel, light, view) queries and at
// arbitrary directions. The GPU's answers are compared with
//   - the exporter's CPU emulation of the shader (Exporter::emulate): both read the same stored
//     texel values and differ only by float32 arithmetic order, so the bound is a small multiple
//     of float epsilon;
//   - the model's own eval at measured directions: the export adds only the half-float rounding
//     of the stored values (rgba16f: relative 2^-11 per stored value), so the bound is derived
//     from that (see half_bound()).
// Codecs are looped over by name (all_cases()): a codec without a row of its own is run at its
// default spec, so a new exporter is tested here as soon as its line is in codecs/registry.cpp. The measured maxima are
// printed ("[gl] ...") and recorded as test properties.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <random>

#include "codecs/codec.h"
#include "core/synth.h"
#include "formats/gpu/export.h"
#include "formats/gpu/ktx2.h"
#include "tests/gl/egl_runner.h"

using namespace btfc;
namespace fs = std::filesystem;

namespace {

constexpr double k_half_eps = 1.0 / 2048;       // unit roundoff of half floats (11-bit significand)
constexpr double k_float_eps = 1.0 / 16777216;  // float32 (24-bit significand)
constexpr int k_dir_map = 64;                   // ExportOptions::direction_map used here

struct Case {
  const char* codec;
  const char* name;
  const char* spec;
  float scale;       // synthetic value scale (1e6: HDR beyond the half range)
  bool half;         // export storage rgba16f (else rgba32f)
  // How much a relative error of the stored values grows in the decoded value, relative to
  // |value| + rms: 1 for decoders linear in the stored values; 2 for fmf's log-luminance
  // (dfmf: Y = exp(Ylog), dY = Y dYlog, and |Ylog| = ln(1 / Y) is ~2 for the bright values that
  // dominate |value| + rms). A codec whose decoder cancels more states it here.
  double amplification;
  // The export rounds values the model keeps at higher precision, so GL != model is expected
  // and the comparison must resolve that rounding (checked: max error >= 0.2 of the bound).
  // fmf precision=half keeps SxV as half(x / s_c) * s_c; the export stores x / s_c with the
  // same per-component scales, so a half model is exported exactly (not lossy).
  bool lossy_storage;
  // Extra factor on the GL-vs-emulation bound for interpolated queries of shaders that map
  // directions through transcendental functions: mlvq computes its (phi, theta, alpha, beta) grid
  // coordinates with atan / sqrt, whose llvmpipe results differ from glibc's in the last bits
  // and move the multilinear weights (measured up to 1.2e-4 relative on llvmpipe).
  double interp_arith = 1;
};

const Case k_cases[] = {
    {"fmf", "rgb", "fmf:rank=6", 1, true, 1, false},
    {"fmf", "rgb_float_factors", "fmf:rank=6:precision=float", 1, true, 1, true},
    {"fmf", "dfmf", "fmf:color=dfmf:rank=6:chroma_rank=3:precision=float:offset=1e-5", 1, true, 2, true},
    {"fmf", "dfmf_auto_offset", "fmf:color=dfmf:rank=6:chroma_rank=3:precision=float", 1, true, 2, true},
    {"fmf", "hdr", "fmf:rank=6:precision=float", 1e6f, true, 1, true},
    {"fmf", "rgba32f", "fmf:rank=6:precision=float", 1, false, 1, false},
    {"lpyr", "ldr", "lpyr:y=4:c=1", 1, true, 1, false},
    {"lpyr", "hdr", "lpyr:y=4:c=1", 1e6f, true, 1, false},
    {"lpca", "ldr", "lpca:clusters=4:components=3:iters=3", 1, true, 1, false},
    {"lpca", "hdr", "lpca:clusters=4:components=3:iters=3", 1e6f, true, 1, false},
    {"mlvq", "ldr", "mlvq:phi=8:theta=4:alpha=7:beta=7", 1, true, 1, false, 16},
    {"mlvq", "hdr", "mlvq:phi=8:theta=4:alpha=7:beta=7", 1e6f, true, 1, false, 16},
};

// The table above, plus every registered codec with an exporter that has no row there, at its
// default spec on LDR and HDR data (linear decoder, half storage as exported): a new codec is
// tested here as soon as its line is in codecs/registry.cpp (or, for the test-only codec,
// tests/toy_codec/register.cpp, linked into this test too). Evaluated when the tests are
// registered, after every static registration.
std::vector<Case> all_cases() {
  std::vector<Case> v(std::begin(k_cases), std::end(k_cases));
  for (const CodecEntry& e : codec_registry()) {
    if (!e.exporter) continue;
    const std::string name = e.codec->name();
    if (std::any_of(std::begin(k_cases), std::end(k_cases), [&](const Case& c) { return name == c.codec; })) continue;
    v.push_back({e.codec->name(), "default_ldr", e.codec->name(), 1, true, 1, false});
    v.push_back({e.codec->name(), "default_hdr", e.codec->name(), 1e6f, true, 1, false});
  }
  return v;
}

const Btf& synthetic(float scale) {
  static std::map<float, Btf> cache;  // node-based: references stay valid
  if (auto it = cache.find(scale); it != cache.end()) return it->second;
  SynthOptions o;
  o.width = 16, o.height = 12, o.seed = 7, o.scale = scale;
  auto b = synthesize_btf(o);
  EXPECT_TRUE(b.ok()) << b.status().message();
  return cache.emplace(scale, std::move(b).value()).first->second;
}

// A unit direction in the upper hemisphere whose parabolic coordinates lie at least 0.1 cell
// inside a cell of the n x n direction maps: GPU and CPU compute the cell with different float
// rounding, and a query on a cell boundary would compare two different (both right) cells.
Vec3 random_direction(std::mt19937& rng) {
  std::uniform_real_distribution<double> u(-1, 1);
  for (;;) {
    const double px = u(rng) * 0.97, py = u(rng) * 0.97, r2 = px * px + py * py;
    if (r2 > 0.97 * 0.97) continue;
    auto inside = [](double p) {
      const double c = (p * 0.5 + 0.5) * k_dir_map, f = c - std::floor(c);
      return f > 0.1 && f < 0.9;
    };
    if (!inside(px) || !inside(py)) continue;
    const double s = 1 / (1 + r2);
    return Vec3{float(2 * px * s), float(2 * py * s), float((1 - r2) * s)};
  }
}

struct Grid {
  std::vector<gpu::ShaderQuery> q;
  std::vector<int> x, y;  // texel of each query
};

// 16 texels (corners, edges, interior) x (50 measured pairs + 40 arbitrary direction pairs).
Grid make_grid(const BtfDesc& d) {
  Grid g;
  const int nl = int(d.num_lights()), nv = int(d.num_views());
  std::mt19937 rng(11);
  std::vector<std::pair<Vec3, Vec3>> dirs;
  for (int i = 0; i < 40; ++i) dirs.emplace_back(random_direction(rng), random_direction(rng));
  for (int x : {0, d.width / 3, 2 * d.width / 3, d.width - 1})
    for (int y : {0, d.height / 3, 2 * d.height / 3, d.height - 1}) {
      gpu::ShaderQuery q;
      q.u = (float(x) + 0.5f) / float(d.width), q.v = (float(y) + 0.5f) / float(d.height);
      for (int i = 0; i < 50; ++i) {
        q.light = i == 49 ? nl - 1 : (i * 37 + 3 * x) % nl;
        q.view = i == 49 ? nv - 1 : (i * 53 + 5 * y) % nv;
        g.q.push_back(q), g.x.push_back(x), g.y.push_back(y);
      }
      q.light = q.view = -1;
      for (const auto& [wl, wv] : dirs) {
        q.wl = wl, q.wv = wv;
        g.q.push_back(q), g.x.push_back(x), g.y.push_back(y);
      }
    }
  return g;
}

std::string work_dir(const std::string& name) {
  const fs::path p = fs::path(::testing::TempDir()) / ("gl_export_" + std::to_string(::getpid()) + "_" + name);
  fs::remove_all(p);
  return p.string();
}

// Per-query bound of |GL - model| from half storage. A decoded value is a sum of products of
// two stored values, sum_j t_j a_j; storing each with a relative rounding error <= u = 2^-11
// changes it by at most 2u sum_j |t_j a_j|. Allowing the components to cancel down to half of
// |value| + rms (the rms term covers small values made of larger components) gives
// 4u (|value| + rms), times the decoder's amplification (Case); plus the float32 arithmetic
// of arith_bound (all of the rgba32f case).
double half_bound(const Case& c, double value, double rms) {
  const double u = c.half ? k_half_eps : 0.0;
  return (4 * u + 64 * k_float_eps) * c.amplification * (std::fabs(value) + rms);
}
// Per-query bound of |GL - emulation|: the same stored values in float32, summed in another
// order, with GPU exp / division: 64 float ulps of (|value| + rms).
double arith_bound(const Case& c, double value, double rms) { return 64 * c.amplification * k_float_eps * (std::fabs(value) + rms); }

class GlExport : public ::testing::TestWithParam<Case> {};

TEST_P(GlExport, GpuMatchesEmulationAndModel) {
  const Case& c = GetParam();
  const gpu::Exporter* ex = gpu::find_exporter(c.codec);
  if (!ex) GTEST_SKIP() << c.codec << " has no GPU exporter yet (codecs/registry.cpp)";
  if (Status s = gltest::gl_context(); !s.ok()) GTEST_SKIP() << "no OpenGL ES here: " << s.message();

  const Btf& btf = synthetic(c.scale);
  auto spec = resolve_spec(c.spec);
  ASSERT_TRUE(spec.ok()) << spec.status().message();
  Context ctx;
  auto model = spec->first->encode(btf, spec->second, ctx);
  ASSERT_TRUE(model.ok()) << model.status().message();
  const Model& m = *model.value();
  gpu::ExportOptions opt;
  opt.half = c.half, opt.direction_map = k_dir_map;
  auto bundle = gpu::build_export(m, opt);
  ASSERT_TRUE(bundle.ok()) << bundle.status().message();
  EXPECT_EQ(bundle->clamped(), 0u) << "the default export scales instead of clamping";
  const std::string dir = work_dir(std::string(c.codec) + "_" + c.name);
  ASSERT_TRUE(gpu::write_export_dir(bundle.value(), dir, false).ok());

  const Grid g = make_grid(m.desc());
  auto gl = gltest::gl_eval(dir, g.q);
  ASSERT_TRUE(gl.ok()) << gl.status().message();

  // Model values at the measured queries, their rms (the scale of the tolerances).
  const int ch = m.desc().channels;
  std::vector<float> model_v(g.q.size() * 3, 0.f), emu(g.q.size() * 3, 0.f);
  double ss = 0;
  size_t n_measured = 0;
  for (size_t i = 0; i < g.q.size(); ++i) {
    ex->emulate(bundle.value(), g.q[i], &emu[i * 3]);
    if (g.q[i].light < 0) continue;
    float v[4] = {0, 0, 0, 0};
    m.eval(g.x[i], g.y[i], g.q[i].light, g.q[i].view, v);
    for (int k = 0; k < ch && k < 3; ++k) model_v[i * 3 + size_t(k)] = v[k], ss += double(v[k]) * v[k];
    ++n_measured;
  }
  const double rms = std::sqrt(ss / double(n_measured * size_t(std::min(ch, 3))));
  ASSERT_GT(rms, 0);

  double e_emu = 0, e_emu_rel = 0, e_model = 0, e_model_rel = 0, e_dir = 0;
  int bad_emu = 0, bad_model = 0;
  for (size_t i = 0; i < g.q.size(); ++i) {
    const bool measured = g.q[i].light >= 0;
    float dir_v[4] = {0, 0, 0, 0};
    if (!measured) {
      ASSERT_TRUE(m.eval_dir(g.x[i], g.y[i], g.q[i].wl, g.q[i].wv, dir_v).ok());
    }
    for (int k = 0; k < 3; ++k) {
      const double G = (*gl)[i * 3 + size_t(k)], E = emu[i * 3 + size_t(k)];
      ASSERT_TRUE(std::isfinite(G)) << "query " << i;
      const double de = std::fabs(G - E), tb = arith_bound(c, E, rms) * (measured ? 1.0 : c.interp_arith);
      e_emu = std::max(e_emu, de), e_emu_rel = std::max(e_emu_rel, de / tb);
      if (de > tb && ++bad_emu <= 5)
        ADD_FAILURE() << "GL vs emulation, query " << i << " texel (" << g.x[i] << ", " << g.y[i] << ") light " << g.q[i].light
                      << " view " << g.q[i].view << " channel " << k << ": " << G << " vs " << E << " (bound " << tb << ")";
      if (!measured) {
        if (k < ch) e_dir = std::max(e_dir, std::fabs(G - dir_v[k]));
        continue;
      }
      const double M = model_v[i * 3 + size_t(k)], dm = std::fabs(G - M), hb = half_bound(c, M, rms);
      e_model = std::max(e_model, dm), e_model_rel = std::max(e_model_rel, dm / hb);
      if (dm > hb && ++bad_model <= 5)
        ADD_FAILURE() << "GL vs model, query " << i << " texel (" << g.x[i] << ", " << g.y[i] << ") light " << g.q[i].light << " view "
                      << g.q[i].view << " channel " << k << ": " << G << " vs " << M << " (bound " << hb << ")";
    }
  }
  EXPECT_EQ(bad_emu, 0);
  EXPECT_EQ(bad_model, 0);
  if (c.lossy_storage) {  // the comparison resolves the half rounding: the bound is not loose
    EXPECT_GT(e_model, 4 * e_emu) << "GL equals the model more closely than half storage allows";
    EXPECT_GE(e_model_rel, 0.2) << "max |GL - model| is below 0.2 of the half-storage bound: bound too loose";
  }
  std::printf("[gl] %s/%s (%s, %s): %zu queries (%zu measured); rms %.4g; max|GL-emulation| %.3g (%.2f of bound); "
              "max|GL-model| %.3g (%.2f of bound, %.3g rel. to rms); max|GL-eval_dir| %.3g (info: direction maps vs exact Delaunay)\n",
              c.codec, c.name, c.spec, c.half ? "rgba16f" : "rgba32f", g.q.size(), n_measured, rms, e_emu, e_emu_rel, e_model, e_model_rel,
              e_model / rms, e_dir);
  RecordProperty("max_gl_vs_emulation", std::to_string(e_emu));
  RecordProperty("max_gl_vs_model", std::to_string(e_model));
  RecordProperty("rms", std::to_string(rms));
  if (!HasFailure()) fs::remove_all(dir);
}

INSTANTIATE_TEST_SUITE_P(Codecs, GlExport, ::testing::ValuesIn(all_cases()),
                         [](const ::testing::TestParamInfo<Case>& i) { return std::string(i.param.codec) + "_" + i.param.name; });

// The harness must be able to fail: an altered texture file, a broken shader and a manifest
// that disagrees with its files are all noticed.
class GlHarness : public ::testing::Test {
 protected:
  void SetUp() override {
    if (Status s = gltest::gl_context(); !s.ok()) GTEST_SKIP() << "no OpenGL ES here: " << s.message();
    auto spec = resolve_spec("fmf:rank=4");
    ASSERT_TRUE(spec.ok());
    Context ctx;
    auto model = spec->first->encode(synthetic(1), spec->second, ctx);
    ASSERT_TRUE(model.ok()) << model.status().message();
    auto b = gpu::build_export(*model.value(), gpu::ExportOptions{});
    ASSERT_TRUE(b.ok()) << b.status().message();
    bundle = std::move(b).value();
    dir = work_dir(std::string("harness_") + ::testing::UnitTest::GetInstance()->current_test_info()->name());
    ASSERT_TRUE(gpu::write_export_dir(bundle, dir, false).ok());
    gpu::ShaderQuery q;
    q.light = 3, q.view = 5;
    queries = {q};
  }
  void TearDown() override {
    if (!dir.empty()) fs::remove_all(dir);
  }
  gpu::ExportBundle bundle;
  std::string dir;
  std::vector<gpu::ShaderQuery> queries;
};

TEST_F(GlHarness, SeesTheTextureFiles) {
  auto before = gltest::gl_eval(dir, queries);
  ASSERT_TRUE(before.ok()) << before.status().message();
  gpu::GpuTexture t = *bundle.find("eigen_texture");
  for (auto& level : t.f)
    for (float& v : level) v *= 2;  // exact in half
  ASSERT_TRUE(gpu::write_ktx2(t, dir + "/eigen_texture.ktx2").ok());
  auto after = gltest::gl_eval(dir, queries);
  ASSERT_TRUE(after.ok()) << after.status().message();
  for (int k = 0; k < 3; ++k) EXPECT_NEAR((*after)[size_t(k)], 2 * (*before)[size_t(k)], 1e-5 * std::fabs((*before)[size_t(k)])) << k;
  EXPECT_NE((*before)[0], 0.f);
}

TEST_F(GlHarness, ReportsCompileErrorsWithTheLog) {
  std::FILE* f = std::fopen((dir + "/btf.frag").c_str(), "ab");
  ASSERT_TRUE(f);
  std::fputs("vec3 broken( { \n", f);
  std::fclose(f);
  auto r = gltest::gl_eval(dir, queries);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("btf.frag"), std::string::npos) << r.status().message();
  EXPECT_NE(r.status().message().find("compile failed"), std::string::npos) << r.status().message();
}

TEST_F(GlHarness, RejectsAManifestThatDisagreesWithItsFiles) {
  gpu::GpuTexture t = *bundle.find("eigen_abrdf");
  t.f.resize(1);
  t.width -= 1;  // a different shape than the manifest says
  t.f[0].resize(t.level_values(0));
  ASSERT_TRUE(gpu::write_ktx2(t, dir + "/eigen_abrdf.ktx2").ok());
  auto r = gltest::gl_eval(dir, queries);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("eigen_abrdf.ktx2"), std::string::npos) << r.status().message();
  EXPECT_NE(r.status().message().find("disagrees with manifest.json"), std::string::npos) << r.status().message();
}

}  // namespace
