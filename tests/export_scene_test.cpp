// Scene budgets (core/scene.h): scene.json parsing, what the fmf export keeps for a
// scene (mip levels, directions in cones, components within a GPU budget), the predicted error,
// and the cut model model.bsvtf is built from.
#include <gtest/gtest.h>

#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <random>

#include "codecs/fmf/fmf.h"
#include "core/interp.h"
#include "formats/bsvtf/bsvtf.h"
#include "formats/gpu/export.h"
#include "tests/export_test_util.h"

using namespace btfc;
using namespace btfc::gpu;
using btfc::export_test::encode_spec;
using btfc::export_test::rms_of;
using btfc::export_test::synth_ubo;

TEST(Scene, ParseErrorsNameTheKey) {
  EXPECT_FALSE(parse_scene("{", "s.json").ok());
  auto e = parse_scene(R"({"materials": [{"footprnt": [1, 2]}]})", "s.json");
  ASSERT_FALSE(e.ok());
  EXPECT_NE(e.status().message().find("unknown key 'footprnt'"), std::string::npos) << e.status().message();
  EXPECT_FALSE(parse_scene(R"({"materials": [{"footprint": [4, 2]}]})", "s.json").ok());
  EXPECT_FALSE(parse_scene(R"({"materials": [{"light_cone": {"theta": 100, "angle": 10}}]})", "s.json").ok());
  EXPECT_FALSE(parse_scene(R"({"materials": [{"gpu_budget": "lots"}]})", "s.json").ok());
  EXPECT_FALSE(parse_scene(R"({"materials": [{"name": "a"}]})", "s.json", "b").ok());
  auto ok = parse_scene(R"({"materials": [{"name": "a"}, {"name": "b", "footprint": [3, 9], "gpu_budget": "1M"}]})", "s.json", "b");
  ASSERT_TRUE(ok.ok()) << ok.status().message();
  EXPECT_EQ(ok->gpu_budget, 1u << 20);
  int m0, m1;
  scene_mip_range(ok.value(), m0, m1);
  EXPECT_EQ(m0, 1);
  EXPECT_EQ(m1, 5);
}

// fmf and lpca keep the directions inside the cones (widened); inside them the export renders
// exactly what the full export renders.
TEST(Scene, ConesKeepWhatInterpolationInsideThemNeeds) {
  const Btf b = synth_ubo(9, 7);
  for (const std::string spec : {"fmf:rank=8", "lpca:clusters=3:components=4:precision=float"}) {
  SCOPED_TRACE(spec);
  auto m = encode_spec(b, spec);
  ASSERT_TRUE(m);
  ExportOptions full, cut;
  full.half = cut.half = false;
  cut.scene = parse_scene(R"({"materials": [{"light_cone": {"theta": 40, "phi": 90, "angle": 20},
                                              "view_cone": {"theta": 10, "phi": 0, "angle": 15}}]})", "s").value();
  auto bf = build_export(*m, full).value(), bc = build_export(*m, cut).value();
  const size_t nl = bc.evaluation["light_indices"].size(), nv = bc.evaluation["view_indices"].size();
  EXPECT_LT(nl, b.desc().num_lights());
  EXPECT_LT(nv, b.desc().num_views());
  EXPECT_GT(nl, 3u);
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> r01(0, 1);
  double worst = 0;
  const double rms = rms_of(b);
  for (int k = 0; k < 300; ++k) {
    ShaderQuery q;
    q.u = float(r01(rng)), q.v = float(r01(rng));
    // Directions well inside the cones (the cell centres the maps use stay inside too).
    const double a1 = 15 * M_PI / 180 * std::sqrt(r01(rng)), p1 = 2 * M_PI * r01(rng);
    const double a2 = 10 * M_PI / 180 * std::sqrt(r01(rng)), p2 = 2 * M_PI * r01(rng);
    const Vec3 la = dir_from_theta_phi(40 * M_PI / 180, M_PI / 2), va = dir_from_theta_phi(10 * M_PI / 180, 0);
    // Rotate a small-cap sample around each axis: offset in theta/phi is close enough for a cone test.
    double th, ph;
    dir_to_theta_phi(la, th, ph);
    q.wl = dir_from_theta_phi(th + a1 * std::cos(p1), ph + a1 * std::sin(p1) / std::max(std::sin(th), 0.2));
    dir_to_theta_phi(va, th, ph);
    q.wv = dir_from_theta_phi(std::fabs(th + a2 * std::cos(p2)), ph + a2 * std::sin(p2) / std::max(std::sin(th), 0.2));
    float x[3], y[3];
    find_exporter(bf.codec)->emulate(bf, q, x);
    find_exporter(bc.codec)->emulate(bc, q, y);
    for (int c = 0; c < 3; ++c) worst = std::max(worst, double(std::fabs(x[c] - y[c])) / rms);
  }
  EXPECT_LE(worst, 1e-5);
  }
}

TEST(Scene, FootprintDropsFineMipsAndBudgetCutsComponentsWithPredictedError) {
  const Btf b = synth_ubo(16, 16);
  auto m = encode_spec(b, "fmf:rank=16");
  ASSERT_TRUE(m);
  ExportOptions full;
  full.half = false;
  auto bf = build_export(*m, full).value();
  ExportOptions far = full;
  far.scene = parse_scene(R"({"materials": [{"footprint": [4, 4]}]})", "s").value();
  auto bfar = build_export(*m, far).value();
  const GpuTexture &tf = *bf.find("eigen_texture"), &tc = *bfar.find("eigen_texture");
  EXPECT_EQ(tc.width, 4u);
  EXPECT_EQ(tc.f[0], tf.f[2]);  // level 0 of the cut export is level 2 of the full chain
  EXPECT_EQ(tc.num_levels(), 2u);  // levels 2 and 3 (log2 4, + 1 for trilinear blending)
  EXPECT_EQ(bfar.scene_report["predicted_added_rel_error"].get<double>(), 0.0);

  // A budget that forces 16 -> 8 components: the error it adds is what Eckart-Young predicts.
  ExportOptions tight = full;
  tight.scene = parse_scene(R"({"materials": [{"gpu_budget": 800000}]})", "s").value();
  auto bt = build_export(*m, tight);
  ASSERT_TRUE(bt.ok()) << bt.status().message();
  EXPECT_LE(bt->texture_bytes(), 800000u);
  EXPECT_EQ(bt->scene_report["predicted_bytes"].get<uint64_t>(), bt->texture_bytes());
  const int kept = bt->scene_report["components_kept"][0].get<int>();
  EXPECT_LT(kept, 16);
  EXPECT_GE(kept, 4);
  double num = 0, den = 0;
  for (int l = 0; l < 81; l += 4)
    for (int v = 0; v < 81; v += 4)
      for (int y = 0; y < 16; ++y)
        for (int x = 0; x < 16; ++x) {
          ShaderQuery q;
          q.u = (x + 0.5f) / 16, q.v = (y + 0.5f) / 16, q.light = l, q.view = v;
          float a[3], c[3];
          find_exporter("fmf")->emulate(bf, q, a);
          find_exporter("fmf")->emulate(bt.value(), q, c);
          for (int k = 0; k < 3; ++k) num += double(a[k] - c[k]) * (a[k] - c[k]), den += double(a[k]) * a[k];
        }
  const double measured = std::sqrt(num / den), predicted = bt->scene_report["predicted_added_rel_error"].get<double>();
  std::printf("  budget cut to %d components: predicted added rel. error %.4f, measured %.4f\n", kept, predicted, measured);
  EXPECT_GE(measured, 0.75 * predicted);
  EXPECT_LE(measured, 1.25 * predicted);
  ExportOptions impossible = full;
  impossible.scene = parse_scene(R"({"materials": [{"gpu_budget": 1000}]})", "s").value();
  auto bi = build_export(*m, impossible);
  ASSERT_FALSE(bi.ok());
  EXPECT_NE(bi.status().message().find("over the scene's GPU budget"), std::string::npos);
}

TEST(Scene, SceneModelIsWhatTheExportKeeps) {
  // model.bsvtf of a scene export is built from fmf_scene_model: it must hold exactly the
  // levels, components and directions of the KTX2 export (float storage: float rounding only).
  const Btf b = synth_ubo(16, 12);
  const double rms = rms_of(b);
  for (const std::string spec : {"fmf:rank=12:precision=float", "fmf:color=dfmf:rank=8:chroma_rank=4:precision=float:offset=1e-5",
                                 "fmf:color=dfmf:rank=8:chroma_rank=4:precision=float"}) {
    auto m = encode_spec(b, spec);
    ASSERT_TRUE(m);
    ExportOptions o;
    o.half = false;
    o.scene = parse_scene(R"({"materials": [{"footprint": [2, 4], "light_cone": {"theta": 45, "phi": 0, "angle": 20},
                                              "gpu_budget": 700000}]})", "s").value();
    auto bundle = build_export(*m, o);
    ASSERT_TRUE(bundle.ok()) << bundle.status().message();
    auto sm = fmf_scene_model(*m, o);
    ASSERT_TRUE(sm.ok()) << sm.status().message();
    const BtfDesc& sd = sm.value()->desc();
    EXPECT_EQ(sd.width, 8);
    EXPECT_EQ(sd.height, 6);
    EXPECT_EQ(sd.num_lights(), bundle->evaluation["light_indices"].size());
    EXPECT_EQ(sd.num_views(), b.desc().num_views());
    double worst = 0;
    for (size_t l = 0; l < sd.num_lights(); l += 3)
      for (size_t v = 0; v < sd.num_views(); v += 7)
        for (int y = 0; y < sd.height; ++y)
          for (int x = 0; x < sd.width; ++x) {
            ShaderQuery q;
            q.u = (x + 0.5f) / float(sd.width), q.v = (y + 0.5f) / float(sd.height), q.light = int(l), q.view = int(v);
            float e[3], w[3] = {0, 0, 0};
            find_exporter("fmf")->emulate(bundle.value(), q, e);
            sm.value()->eval(x, y, int(l), int(v), w);
            for (int c = 0; c < 3; ++c) worst = std::max(worst, std::fabs(double(e[c]) - w[c]) / rms);
          }
    EXPECT_LE(worst, 4e-6) << spec;
    // Its BSVTF keeps the model's luminance offset (colour model 13 unless Bonn's 1e-5).
    if (spec.find("dfmf") != std::string::npos) {
      const std::string p = (std::filesystem::temp_directory_path() / ("btfc_scene_" + std::to_string(::getpid()) + ".bsvtf")).string();
      ASSERT_TRUE(write_bsvtf(*sm.value(), BsvtfOptions{}, p, nullptr).ok()) << spec;
      auto rd = BsvtfReader::open(p);
      std::filesystem::remove(p);
      ASSERT_TRUE(rd.ok()) << rd.status().message();
      const float e = fmf_factors(*m).value().drr_eps;
      EXPECT_EQ(rd->color_model(), e == 1e-5f ? 11 : 13) << spec;
      EXPECT_EQ(rd->luminance_offset(), e) << spec;
    }
  }
}
