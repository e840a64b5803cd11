// GPU export framework (formats/gpu) and the fmf exporter: KTX2 byte layout and round trips,
// hostile KTX2 input, half overflow (scaled or clamped and reported), mip chains, and the fmf
// shader's CPU emulation against the model's own evaluation.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "codecs/codec.h"
#include "codecs/fmf/fmf.h"
#include "codecs/gpu_export.h"
#include "core/interp.h"
#include "core/synth.h"
#include "formats/gpu/export.h"
#include "formats/gpu/ktx2.h"
#include "tests/export_test_util.h"

using namespace btfc;
using namespace btfc::gpu;
using btfc::export_test::encode_spec;
using btfc::export_test::rms_of;
using btfc::export_test::synth_ubo;

namespace {

uint32_t rd32(const std::vector<uint8_t>& b, size_t at) {
  return uint32_t(b[at]) | uint32_t(b[at + 1]) << 8 | uint32_t(b[at + 2]) << 16 | uint32_t(b[at + 3]) << 24;
}
uint64_t rd64(const std::vector<uint8_t>& b, size_t at) { return uint64_t(rd32(b, at)) | uint64_t(rd32(b, at + 4)) << 32; }

// Direction at the centre of the direction-map cell a direction falls in (what the shader uses).
Vec3 cell_centre(const Vec3& d, int n) {
  int cx, cy;
  direction_cell(d, n, cx, cy);
  double px = (cx + 0.5) / n * 2 - 1, py = (cy + 0.5) / n * 2 - 1, r2 = px * px + py * py;
  if (r2 > 1) px /= std::sqrt(r2), py /= std::sqrt(r2), r2 = 1;
  const double s = 1 / (1 + r2);
  return {float(2 * px * s), float(2 * py * s), float((1 - r2) * s)};
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
  const Btf b = synth_ubo(19, 11);
  const double rms = rms_of(b);
  // dfmf with Bonn's offset and with the default one from the data (the shader's DFMF_OFFSET).
  for (const std::string spec : {"fmf:rank=9", "fmf:color=dfmf:rank=6:chroma_rank=3:offset=1e-5", "fmf:rank=9:precision=float",
                                 "fmf:color=dfmf:rank=6:chroma_rank=3:precision=float:offset=1e-5", "fmf:color=dfmf:rank=6:chroma_rank=3",
                                 "fmf:color=dfmf:rank=6:chroma_rank=3:precision=float"}) {
    auto m = encode_spec(b, spec);
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
    if (spec.find("dfmf") != std::string::npos) {
      const float e = bh->evaluation.at("luminance_offset").get<float>();
      EXPECT_EQ(e, fmf_factors(*m)->drr_eps) << spec;
      EXPECT_EQ(e == 1e-5f, spec.find("offset=1e-5") != std::string::npos) << spec << ": offset " << e;
      EXPECT_NE(bh->glsl.find("const float DFMF_OFFSET = " + glsl_float(e) + ";"), std::string::npos) << spec;
    }
  }
}

TEST(FmfExport, HdrNeverOverflowsHalf) {
  // Per-component scales keep every stored eigen-texture value within [-1, 1] (and U is
  // orthonormal), so 1e6-scaled data export to half without clamping, even with clamp_half.
  const Btf b = synth_ubo(8, 8, 1e6f);
  const double rms = rms_of(b);
  for (const std::string spec : {"fmf:rank=8", "fmf:rank=8:precision=float"}) {
    auto m = encode_spec(b, spec);
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
  const Btf b = synth_ubo(8, 8, 1e6f);
  auto m = encode_spec(b, "lpyr:y=2:c=1");
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
  auto m = encode_spec(b, "fmf:rank=1");
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
  const Btf b = synth_ubo(4, 4);
  auto m = encode_spec(b, "fmf:rank=2");
  ASSERT_TRUE(m);
  ExportOptions o;
  o.direction_map = 1;
  EXPECT_EQ(build_export(*m, o).status().code(), StatusCode::invalid_argument);
}
