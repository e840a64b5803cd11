// GPU export framework (formats/gpu) and the fmf exporter: KTX2 byte layout and round trips,
// hostile KTX2 input, half overflow (scaled or clamped and reported), mip chains, and the fmf
// shader's CPU emulation against the model's own evaluation.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "codecs/codec.h"
#include "core/interp.h"
#include "core/synth.h"
#include "codecs/fmf/fmf_export.h"
#include "formats/gpu/export.h"
#include "formats/gpu/ktx2.h"

using namespace btfc;
using namespace btfc::gpu;

namespace {

uint32_t rd32(const std::vector<uint8_t>& b, size_t at) {
  return uint32_t(b[at]) | uint32_t(b[at + 1]) << 8 | uint32_t(b[at + 2]) << 16 | uint32_t(b[at + 3]) << 24;
}
uint64_t rd64(const std::vector<uint8_t>& b, size_t at) { return uint64_t(rd32(b, at)) | uint64_t(rd32(b, at + 4)) << 32; }

std::unique_ptr<Model> encode(const Btf& b, const std::string& spec) {
  auto r = resolve_spec(spec);
  EXPECT_TRUE(r.ok()) << r.status().message();
  Context ctx;
  auto m = r->first->encode(b, r->second, ctx);
  EXPECT_TRUE(m.ok()) << m.status().message();
  return m.ok() ? std::move(m).value() : nullptr;
}

Btf synth(int w, int h, float scale = 1) {
  SynthOptions o;
  o.width = w, o.height = h, o.scale = scale;
  return synthesize_btf(o).value();
}

// Direction at the centre of the direction-map cell a direction falls in (what the shader uses).
Vec3 cell_centre(const Vec3& d, int n) {
  int cx, cy;
  direction_cell(d, n, cx, cy);
  double px = (cx + 0.5) / n * 2 - 1, py = (cy + 0.5) / n * 2 - 1, r2 = px * px + py * py;
  if (r2 > 1) px /= std::sqrt(r2), py /= std::sqrt(r2), r2 = 1;
  const double s = 1 / (1 + r2);
  return {float(2 * px * s), float(2 * py * s), float((1 - r2) * s)};
}

double rms_of(const Btf& b) {
  double s = 0;
  for (size_t i = 0; i < b.size(); ++i) s += double(b.data()[i]) * b.data()[i];
  return std::sqrt(s / double(b.size()));
}

// Max |emulation - model| over measured queries at every texel of a few direction pairs, and at
// arbitrary directions vs eval_dir at the cell centres; relative to the data RMS.
void check_emulation(const Model& m, const ExportBundle& b, double rms, double measured_bound, double dir_bound, double* measured_err = nullptr) {
  const Exporter* e = find_exporter(b.codec);
  ASSERT_NE(e, nullptr);
  const BtfDesc& d = m.desc();
  double worst = 0, worst_dir = 0;
  std::mt19937 rng(3);
  for (int k = 0; k < 6; ++k) {
    const int l = int(rng() % d.num_lights()), v = int(rng() % d.num_views());
    for (int y = 0; y < d.height; ++y)
      for (int x = 0; x < d.width; ++x) {
        ShaderQuery q;
        q.u = (x + 0.5f) / float(d.width), q.v = (y + 0.5f) / float(d.height), q.light = l, q.view = v;
        float got[3], want[3] = {0, 0, 0};
        e->emulate(b, q, got);
        m.eval(x, y, l, v, want);
        for (int c = 0; c < d.channels; ++c) worst = std::max(worst, std::fabs(double(got[c]) - want[c]) / rms);
      }
  }
  std::uniform_real_distribution<double> th(0, 1.3), ph(-M_PI, M_PI);
  const int n = int(b.find("dir_index")->width);
  for (int k = 0; k < 200; ++k) {
    ShaderQuery q;
    const int x = int(rng() % d.width), y = int(rng() % d.height);
    q.u = (x + 0.5f) / float(d.width), q.v = (y + 0.5f) / float(d.height);
    q.wl = dir_from_theta_phi(th(rng), ph(rng)), q.wv = dir_from_theta_phi(th(rng), ph(rng));
    float got[3], want[3] = {0, 0, 0};
    e->emulate(b, q, got);
    ASSERT_TRUE(m.eval_dir(x, y, cell_centre(q.wl, n), cell_centre(q.wv, n), want).ok());
    for (int c = 0; c < d.channels; ++c) worst_dir = std::max(worst_dir, std::fabs(double(got[c]) - want[c]) / rms);
  }
  EXPECT_LE(worst, measured_bound);
  EXPECT_LE(worst_dir, dir_bound);
  if (measured_err) *measured_err = worst;
  std::printf("  %s: emulation vs model, max error / RMS: measured %.3g, interpolated %.3g\n", b.spec.c_str(), worst, worst_dir);
}

}  // namespace

TEST(Ktx2, HeaderLayoutAndRoundTripEveryFormat) {
  std::mt19937 rng(1);
  for (int fi = 0; fi <= int(TexFormat::rgba32f); ++fi) {
    const TexFormat f = TexFormat(fi);
    const FormatInfo& info = format_info(f);
    const uint32_t w = 13, h = 7, layers = fi % 2 ? 3 : 0;
    Result<GpuTexture> t = unsupported("");
    const size_t n = size_t(w) * h * (layers ? layers : 1) * size_t(info.channels);
    if (info.is_integer) {
      std::vector<uint32_t> v(n);
      for (auto& x : v) x = rng() % (info.bytes_per_channel == 1 ? 256u : info.bytes_per_channel == 2 ? 65536u : 0xFFFFFFFFu);
      t = make_uint_texture("t", f, w, h, layers, v);
    } else {
      std::vector<float> v(n);
      for (auto& x : v) x = float(rng() % 1000) / 999.f;
      t = make_float_texture("t", f, w, h, layers, v, true);
    }
    ASSERT_TRUE(t.ok()) << t.status().message();
    const std::vector<uint8_t> bytes = encode_ktx2(t.value(), {{"btfc.test", "1"}});
    ASSERT_GE(bytes.size(), 80u);
    EXPECT_EQ(bytes[0], 0xAB);
    EXPECT_EQ(std::string(bytes.begin() + 1, bytes.begin() + 7), "KTX 20");
    EXPECT_EQ(rd32(bytes, 12), info.vk_format);
    EXPECT_EQ(rd32(bytes, 16), uint32_t(info.bytes_per_channel));
    EXPECT_EQ(rd32(bytes, 20), w);
    EXPECT_EQ(rd32(bytes, 24), h);
    EXPECT_EQ(rd32(bytes, 32), layers);
    EXPECT_EQ(rd32(bytes, 40), t->num_levels());
    // DFD: total size = 4 + 24 + 16 * channels; bytesPlane0 = texel size.
    const uint32_t dfd = rd32(bytes, 48);
    EXPECT_EQ(rd32(bytes, 52), uint32_t(28 + 16 * info.channels));
    EXPECT_EQ(rd32(bytes, dfd + 20), uint32_t(info.channels * info.bytes_per_channel));
    // Levels: smallest first in the file, aligned, exact lengths.
    uint64_t prev_off = UINT64_MAX;
    for (uint32_t m = 0; m < t->num_levels(); ++m) {
      const uint64_t off = rd64(bytes, 80 + 24 * m), len = rd64(bytes, 80 + 24 * m + 8);
      EXPECT_EQ(len, t->level_values(m) * size_t(info.bytes_per_channel));
      EXPECT_EQ(off % 4, 0u);
      EXPECT_EQ(off % size_t(info.channels * info.bytes_per_channel), 0u);
      EXPECT_LT(off, prev_off);
      prev_off = off;
    }
    KeyValues kv;
    auto back = decode_ktx2(bytes, "mem", &kv);
    ASSERT_TRUE(back.ok()) << back.status().message();
    EXPECT_EQ(back->f, t->f);
    EXPECT_EQ(back->u, t->u);
    ASSERT_EQ(kv.size(), 2u);
    EXPECT_EQ(kv[0].first, "KTXwriter");
    EXPECT_EQ(kv[1], (std::pair<std::string, std::string>("btfc.test", "1")));
  }
}

TEST(Ktx2, HostileInputNamesTheProblem) {
  auto t = make_float_texture("t", TexFormat::rgba16f, 8, 8, 2, std::vector<float>(8 * 8 * 2 * 4, 0.5f), true).value();
  const std::vector<uint8_t> good = encode_ktx2(t);
  auto expect_corrupt = [](std::vector<uint8_t> b, const char* what) {
    auto r = decode_ktx2(b, "x.ktx2");
    ASSERT_FALSE(r.ok()) << what;
    EXPECT_NE(r.status().message().find("x.ktx2"), std::string::npos) << r.status().message();
  };
  std::vector<uint8_t> b = good;
  b[3] = 'Y';
  expect_corrupt(b, "magic");
  expect_corrupt(std::vector<uint8_t>(good.begin(), good.begin() + 40), "truncated header");
  expect_corrupt(std::vector<uint8_t>(good.begin(), good.end() - 10), "truncated level");
  b = good;
  b[88] ^= 0x40;  // level 0 byteLength
  expect_corrupt(b, "length");
  b = good;
  b[12] = 200;  // vkFormat btfc does not read
  expect_corrupt(b, "format");
  b = good;
  b[16] = 4;  // typeSize disagrees with rgba16f
  expect_corrupt(b, "typeSize");
  for (size_t cut = 0; cut < good.size(); cut += 97) {  // every truncation is an error, never a crash
    auto r = decode_ktx2(std::vector<uint8_t>(good.begin(), good.begin() + long(cut)), "cut.ktx2");
    EXPECT_FALSE(r.ok());
  }
}

TEST(GpuTexture, MipChainIsTheBoxAverageAndOddSizesFold) {
  std::vector<float> v(8 * 4 * 4);
  for (size_t i = 0; i < v.size(); ++i) v[i] = float(i % 17) / 16.f;
  auto t = make_float_texture("m", TexFormat::rgba32f, 8, 4, 0, v, true).value();
  ASSERT_EQ(t.num_levels(), 4u);  // 8x4, 4x2, 2x1, 1x1
  double mean = 0;
  for (size_t i = 0; i < v.size(); i += 4) mean += v[i];
  EXPECT_NEAR(t.f[3][0], mean / 32, 1e-6);
  EXPECT_NEAR(t.f[1][0], (v[0] + v[4] + v[32] + v[36]) / 4, 1e-6);
  // 5 x 3: the last column / row fold into the last child, so the total mean is kept.
  auto o = make_float_texture("o", TexFormat::r32f, 5, 3, 0, {1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15}, true).value();
  EXPECT_EQ(o.num_levels(), 3u);
  EXPECT_EQ(o.level_width(1), 2u);
  EXPECT_NEAR(o.f[1][1], (3 + 4 + 5 + 8 + 9 + 10 + 13 + 14 + 15) / 9.0, 1e-5);
}

TEST(GpuTexture, HalfOverflowIsScaledOrClampedAndCounted) {
  std::vector<float> v = {1e6f, -3e5f, 1.0f, 1e-6f};
  const double s = half_safe_scale(v);
  EXPECT_GE(s, 1e6 / 65504.0);
  EXPECT_LE(s, 4 * 1e6 / 65504.0);
  EXPECT_EQ(s, std::exp2(std::round(std::log2(s))));  // a power of two: scaling is exact
  auto c = make_float_texture("c", TexFormat::rgba16f, 1, 1, 0, v).value();
  EXPECT_EQ(c.clamped, 2u);
  EXPECT_EQ(c.f[0][0], 65504.f);
  EXPECT_EQ(c.f[0][1], -65504.f);
  EXPECT_EQ(half_safe_scale({1.f, -2.f}), 1.0);
  EXPECT_FALSE(make_float_texture("n", TexFormat::rgba16f, 1, 1, 0, {NAN, 0, 0, 0}).ok());
  EXPECT_FALSE(make_uint_texture("u", TexFormat::r8_uint, 1, 1, 0, {256}).ok());
}

TEST(FmfExport, EmulationEqualsModelRgbAndDfmf) {
  const Btf b = synth(19, 11);
  const double rms = rms_of(b);
  for (const std::string spec : {"fmf:rank=9", "fmf:color=dfmf:rank=6:chroma_rank=3", "fmf:rank=9:precision=float",
                                 "fmf:color=dfmf:rank=6:chroma_rank=3:precision=float"}) {
    auto m = encode(b, spec);
    ASSERT_TRUE(m);
    const bool half_model = spec.find("precision=float") == std::string::npos;
    ExportOptions half, full;
    full.half = false;
    auto bh = build_export(*m, half), bf = build_export(*m, full);
    ASSERT_TRUE(bh.ok()) << bh.status().message();
    ASSERT_TRUE(bf.ok()) << bf.status().message();
    // Float storage: float rounding of the 4-wide dot products only.
    check_emulation(*m, bf.value(), rms, 4e-6, 4e-6);
    double err = 0;
    if (half_model) {
      // The eigen-textures are stored over the model's own per-component scales, so a half
      // model's values are stored exactly: float rounding only.
      check_emulation(*m, bh.value(), rms, 4e-6, 4e-6, &err);
    } else {
      // A float model rounded to half: each factor to 11 significant bits; the error must
      // show (two-sided) and stay within a few half ulps of the values.
      check_emulation(*m, bh.value(), rms, 4e-3, 4e-3, &err);
      EXPECT_GE(err, 1e-4);
    }
    EXPECT_EQ(bh->clamped(), 0u);
    EXPECT_TRUE(bh->warnings.empty());
    EXPECT_NE(bh->glsl.find("vec3 btf_eval(vec2 uv, vec3 wl, vec3 wv)"), std::string::npos);
    EXPECT_NE(bh->glsl.find("#ifndef BTFC_NO_MAIN"), std::string::npos);
  }
}

TEST(FmfExport, HdrNeverOverflowsHalf) {
  // Per-component scales keep every stored eigen-texture value within [-1, 1] (and U is
  // orthonormal), so 1e6-scaled data export to half without clamping, even with clamp_half.
  const Btf b = synth(8, 8, 1e6f);
  const double rms = rms_of(b);
  for (const std::string spec : {"fmf:rank=8", "fmf:rank=8:precision=float"}) {
    auto m = encode(b, spec);
    ASSERT_TRUE(m);
    ExportOptions clamp;
    clamp.clamp_half = true;
    for (const ExportOptions& o : {ExportOptions{}, clamp}) {
      auto e = build_export(*m, o);
      ASSERT_TRUE(e.ok());
      EXPECT_EQ(e->clamped(), 0u);
      EXPECT_TRUE(e->warnings.empty());
      check_emulation(*m, e.value(), rms, spec == "fmf:rank=8" ? 4e-6 : 4e-3, spec == "fmf:rank=8" ? 4e-6 : 4e-3);
    }
  }
}

TEST(Export, HalfOverflowClampedAndReportedWhenAsked) {
  // lpyr stores its maps unscaled unless they overflow: with clamp_half the overflow of 1e6-scaled
  // data is clamped, counted per texture and in total, and reported as a warning.
  const Btf b = synth(8, 8, 1e6f);
  auto m = encode(b, "lpyr:y=2:c=1");
  ASSERT_TRUE(m);
  ExportOptions clamp;
  clamp.clamp_half = true;
  auto clamped = build_export(*m, clamp);
  ASSERT_TRUE(clamped.ok()) << clamped.status().message();
  EXPECT_GT(clamped->clamped(), 0u);
  bool warned = false;
  for (const std::string& w : clamped->warnings) warned |= w.find("clamped") != std::string::npos;
  EXPECT_TRUE(warned);
  EXPECT_EQ(manifest_json(clamped.value())["clamped_values"].get<uint64_t>(), clamped->clamped());
  auto scaled = build_export(*m, ExportOptions{});
  ASSERT_TRUE(scaled.ok());
  EXPECT_EQ(scaled->clamped(), 0u);
}

TEST(FmfExport, OneTexelOneDirectionAndManifest) {
  SynthOptions o;
  o.width = 1, o.height = 1;
  o.lights = DirectionSet::single(dir_from_theta_phi(0.3, 0.2));
  o.views = DirectionSet::single(Vec3{0, 0, 1});
  const Btf b = synthesize_btf(o).value();
  auto m = encode(b, "fmf:rank=1");
  ASSERT_TRUE(m);
  auto bundle = build_export(*m, ExportOptions{});
  ASSERT_TRUE(bundle.ok()) << bundle.status().message();
  check_emulation(*m, bundle.value(), std::max(rms_of(b), 1e-6), 8e-3, 8e-3);
  const nlohmann::json j = manifest_json(bundle.value());
  EXPECT_EQ(j["codec"], "fmf");
  EXPECT_EQ(j["textures"].size(), 4u);
  EXPECT_EQ(j["btf"]["lights"].size(), 1u);
  EXPECT_EQ(j["textures"][0]["file"], "eigen_texture.ktx2");
}

TEST(Export, UnknownCodecAndBadOptions) {
  EXPECT_EQ(find_exporter("nope"), nullptr);
  const Btf b = synth(4, 4);
  auto m = encode(b, "fmf:rank=2");
  ASSERT_TRUE(m);
  ExportOptions o;
  o.direction_map = 1;
  EXPECT_EQ(build_export(*m, o).status().code(), StatusCode::invalid_argument);
}

// ---- scene budgets (formats/gpu/scene.h) ----

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

TEST(Scene, ConesKeepWhatInterpolationInsideThemNeeds) {
  const Btf b = synth(9, 7);
  auto m = encode(b, "fmf:rank=8");
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
    find_exporter("fmf")->emulate(bf, q, x);
    find_exporter("fmf")->emulate(bc, q, y);
    for (int c = 0; c < 3; ++c) worst = std::max(worst, double(std::fabs(x[c] - y[c])) / rms);
  }
  EXPECT_LE(worst, 1e-5);
}

TEST(Scene, FootprintDropsFineMipsAndBudgetCutsComponentsWithPredictedError) {
  const Btf b = synth(16, 16);
  auto m = encode(b, "fmf:rank=16");
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
  const Btf b = synth(16, 12);
  const double rms = rms_of(b);
  for (const std::string spec : {"fmf:rank=12:precision=float", "fmf:color=dfmf:rank=8:chroma_rank=4:precision=float"}) {
    auto m = encode(b, spec);
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
  }
}
