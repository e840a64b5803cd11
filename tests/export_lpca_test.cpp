// Tests of the lpca GPU exporter (codecs/lpca/lpca_export.cpp): the shader's CPU emulation
// against the model at measured and interpolated directions (half storage exact for a
// half-precision model, two-sided for a float one), btf_relit against the model's relighting at
// the PRT map's texel centres (8-bit bound, two-sided), the SH texture's packing against the
// relighting, and a 1-channel BTF.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>

#include "codecs/lpca/lpca.h"
#include "codecs/lpca/lpca_export.h"
#include "codecs/lpca/lpca_model.h"
#include "core/sh.h"
#include "tests/export_test_util.h"

using namespace btfc;
using namespace btfc::gpu;
using namespace btfc::export_test;

namespace {


// Worst-case error of a half export of a float-precision model at measured (l, v).
double lpca_half_bound(const lpca::LpcaModel& m, int x, int y, int l, int v, int ch) {
  const size_t t = size_t(x) + size_t(m.desc().width) * size_t(y);
  const int c = m.components();
  const Eigen::Index r0 = Eigen::Index(m.cluster_of()[t]) * (c + 1), col = Eigen::Index(m.desc().row(size_t(l), size_t(v), size_t(ch)));
  double b = std::abs(m.table()(r0, col)) * k_half_rel + k_half_abs * m.table().row(r0).cwiseAbs().maxCoeff();
  for (int i = 0; i < c; ++i) {
    const double w = m.weights()(Eigen::Index(t), i), e = m.table()(r0 + 1 + i, col);
    b += std::abs(w * e) * 2.01 * k_half_rel + k_half_abs * (std::abs(e) + std::abs(w));
  }
  return b;
}

TEST(LpcaExport, MeasuredAndInterpolatedMatchModel) {
  Btf btf = synth(13, 9);
  for (const char* spec : {"lpca:clusters=3:components=5", "lpca:clusters=4:components=3:precision=float"}) {
    auto m = encode(lpca_codec(), btf, spec);
    ASSERT_TRUE(m);
    const auto& lm = dynamic_cast<const lpca::LpcaModel&>(*m);
    const bool half_model = lm.config().half;
    const ExportBundle bh = bundle(*m, true), bf = bundle(*m, false);
    const BtfDesc& d = m->desc();
    Errors eh, ef;
    for (int y = 0; y < d.height; ++y)
      for (int x = 0; x < d.width; ++x)
        for (int l = 0; l < int(d.num_lights()); l += 3)
          for (int v = 0; v < int(d.num_views()); ++v) {
            ShaderQuery q = at_texel(d, x, y);
            q.light = l, q.view = v;
            float ref[3], gh[3], gf[3];
            m->eval(x, y, l, v, ref);
            find_exporter("lpca")->emulate(bh, q, gh);
            find_exporter("lpca")->emulate(bf, q, gf);
            for (int c = 0; c < 3; ++c) {
              // A half-precision model's values are stored exactly (its own scales): float tolerance.
              const double bound = (half_model ? 0 : lpca_half_bound(lm, x, y, l, v, c)) + float_tol(ref);
              const double e1 = std::abs(gh[c] - ref[c]), e2 = std::abs(gf[c] - ref[c]);
              eh.max_err = std::max(eh.max_err, e1), eh.max_ratio = std::max(eh.max_ratio, e1 / bound), eh.within &= e1 <= bound;
              ef.max_err = std::max(ef.max_err, e2), ef.within &= e2 <= float_tol(ref);
            }
          }
    std::printf("lpca %s: half export max |err| %.3g (max err/bound %.3f), float export max |err| %.3g\n", spec, eh.max_err, eh.max_ratio, ef.max_err);
    EXPECT_TRUE(eh.within) << spec;
    EXPECT_TRUE(ef.within) << spec;
    if (!half_model) {
      EXPECT_GT(eh.max_ratio, 0.1) << spec;  // float values rounded to half: the loss shows
    }
    // Arbitrary directions at direction-map cell centres: the model's Delaunay eval_dir.
    const std::vector<Vec3> dl = random_cell_centres(32, 10, 4), dv = random_cell_centres(32, 10, 5);
    for (int y = 0; y < d.height; y += 2)
      for (int x = 0; x < d.width; x += 2)
        for (size_t i = 0; i < dl.size(); ++i) {
          ShaderQuery q = at_texel(d, x, y);
          q.wl = dl[i], q.wv = dv[(i * 3) % dv.size()];
          float ref[3], g[3];
          ASSERT_TRUE(m->eval_dir(x, y, q.wl, q.wv, ref).ok());
          find_exporter("lpca")->emulate(bf, q, g);
          for (int c = 0; c < 3; ++c) EXPECT_LE(std::abs(g[c] - ref[c]), float_tol(ref)) << spec;
        }
  }
}

double env_value(double x, double y, double z, int c) {
  const double dot = x * 0.48 + y * 0.3 + z * 0.82;
  return 0.3 + 0.1 * c + 0.2 * z + (1.0 - 0.3 * c) * std::exp(3.0 * (dot - 1.0));
}

EnvironmentSH test_env() {
  EnvironmentSH env;
  env.order = 5;
  for (int c = 0; c < 3; ++c) {
    auto p = sh::project_function(5, [c](double x, double y, double z) { return env_value(x, y, z, c); }, 100);
    env.coeffs.insert(env.coeffs.end(), p.begin(), p.end());
  }
  return env;
}

TEST(LpcaExport, RelitMatchesModelRelightingAtPrtTexelCentres) {
  Btf btf = synth(11, 7);
  auto m = encode(lpca_codec(), btf, "lpca:clusters=3:components=5");
  ASSERT_TRUE(m);
  EXPECT_EQ(bundle(*m, true).find("prt"), nullptr);
  EXPECT_EQ(bundle(*m, true).glsl.find("btf_relit"), std::string::npos);
  const EnvironmentSH env = test_env();
  ASSERT_TRUE(attach_environment(*m, env).ok());
  const ExportBundle b = bundle(*m, true);
  ASSERT_NE(b.find("prt"), nullptr);
  EXPECT_NE(b.glsl.find("vec3 btf_relit(vec2 uv, vec3 wv)"), std::string::npos);
  const auto& lm = dynamic_cast<const lpca::LpcaModel&>(*m);
  const float s0 = b.evaluation["prt_scale"][0], s1 = b.evaluation["prt_scale"][1];
  const BtfDesc& d = m->desc();
  double max_err = 0, max_ratio = 0;
  for (int cy = 1; cy < 16; cy += 3)
    for (int cx = 1; cx < 16; cx += 3) {
      Vec3 wv;
      if (!cell_centre(cx, cy, 16, wv) || wv.z < 0.15f) continue;
      int w, h;
      auto r = relight(*m, env, wv, w, h);
      ASSERT_TRUE(r.ok()) << r.status().message();
      for (int y = 0; y < d.height; ++y)
        for (int x = 0; x < d.width; ++x) {
          const size_t t = size_t(y) * size_t(d.width) + size_t(x);
          double bound = 0.5 / 127.5 * s0 + 1e-6;  // 8-bit rounding of every lambda
          for (int i = 0; i < lm.components(); ++i) bound += 0.5 / 127.5 * s1 * std::abs(lm.weights()(Eigen::Index(t), i));
          float g[3];
          lpca_emulate_relit(b, (float(x) + 0.5f) / float(d.width), (float(y) + 0.5f) / float(d.height), wv, g);
          for (int c = 0; c < 3; ++c) {
            const double e = std::abs(g[c] - (*r)[t * 3 + size_t(c)]);
            max_err = std::max(max_err, e), max_ratio = std::max(max_ratio, e / bound);
            EXPECT_LE(e, bound) << "cell " << cx << "," << cy << " texel " << x << "," << y;
          }
        }
    }
  std::printf("lpca btf_relit vs relight at PRT texel centres: max |err| %.3g, max err/bound %.3f\n", max_err, max_ratio);
  EXPECT_GT(max_ratio, 0.25);  // the 8-bit storage shows: the bound is not loose by orders
}

// The SH texture's packing (manifest "sh"): sum_m beta_m <e^v_{m,k}, a> from its texels equals the
// model's relighting at a measured view (where the view weights are (1, 0, 0) on that view).
TEST(LpcaExport, ShTexturePackingReproducesRelighting) {
  auto m = encode(lpca_codec(), synth(9, 7), "lpca:clusters=3:components=5");
  ASSERT_TRUE(m);
  const EnvironmentSH env = test_env();
  const ExportBundle b = bundle(*m, false);
  const GpuTexture &S = *b.find("eigen_sh"), &CS = *b.find("cluster_scale"), &CI = *b.find("cluster_index");
  const auto& lm = dynamic_cast<const lpca::LpcaModel&>(*m);
  const BtfDesc& d = m->desc();
  const int C = lm.components(), n2 = b.evaluation["sh_coefficients"], SP = b.evaluation["sh_texels_per_row"], nc = d.channels;
  double max_err = 0;
  for (int v : {0, 3, 7}) {
    int w, h;
    auto r = relight(*m, env, d.views.dirs[size_t(v)], w, h);
    ASSERT_TRUE(r.ok()) << r.status().message();
    for (size_t t = 0; t < d.num_texels(); ++t) {
      const size_t k = CI.u[0][t];
      for (int c = 0; c < nc; ++c) {
        double L = 0;
        for (int mm = 0; mm <= C; ++mm) {
          const double beta = mm == 0 ? CS.f[0][k * CS.width * 4] : lm.weights()(Eigen::Index(t), mm - 1);
          double dot = 0;
          for (int j = 0; j < n2; ++j)
            dot += S.f[0][((k * S.height + size_t(v * nc + c)) * S.width + size_t(mm * SP + j / 4)) * 4 + size_t(j % 4)] * S.scale *
                   env.coeffs[size_t(c * n2 + j)];
          L += beta * dot;
        }
        const double ref = (*r)[t * 3 + size_t(c)];
        max_err = std::max(max_err, std::abs(L - ref));
        EXPECT_NEAR(L, ref, 1e-5 * (1 + std::abs(ref))) << "view " << v << " texel " << t;
      }
    }
  }
  std::printf("lpca eigen_sh texture vs relight at measured views: max |err| %.3g\n", max_err);
}

// A 1-channel BTF: the shader returns (value, 0, 0) (contract: channels beyond the BTF's are 0).
TEST(LpcaExport, OneChannelBtfLeavesOtherChannelsZero) {
  BtfDesc d;
  d.width = 5, d.height = 4, d.channels = 1, d.lights = DirectionSet::ubo2003(), d.views = some_views();
  Btf btf = Btf::create(d).value();
  std::mt19937 rng(9);
  std::uniform_real_distribution<float> u(0.1f, 1.f);
  for (size_t i = 0; i < btf.size(); ++i) btf.data()[i] = u(rng);
  auto m = encode(lpca_codec(), btf, "lpca:clusters=2:components=3");
  ASSERT_TRUE(m);
  const ExportBundle b = bundle(*m, true);
  EXPECT_NE(b.glsl.find("const vec3 CHANNELS = vec3(1.0, 0.0, 0.0);"), std::string::npos);
  for (int i = 0; i < 100; ++i) {
    ShaderQuery q = at_texel(d, i % 5, i % 4);
    q.light = (i * 7) % 81, q.view = i % 8;
    float ref[3] = {0, 0, 0}, g[3];
    m->eval(i % 5, i % 4, q.light, q.view, ref);
    find_exporter("lpca")->emulate(b, q, g);
    EXPECT_LE(std::abs(g[0] - ref[0]), float_tol(ref));
    EXPECT_EQ(g[1], 0.f);
    EXPECT_EQ(g[2], 0.f);
  }
}

}  // namespace
