// GPU export of mlvq (codecs/mlvq/mlvq_export*.cpp): the CPU emulation of the reference shader,
// reading only the exported texel values, against the model's own evaluation, for every colour
// scheme, odd texture sizes, grey and HDR BTFs, float and half storage; KTX2 round trips; the
// shader text against the pinned contract (and glslangValidator when it is installed).
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>

#include "codecs/mlvq/mlvq.h"
#include "core/synth.h"
#include "formats/gpu/export.h"
#include "formats/gpu/ktx2.h"

using namespace btfc;
using namespace btfc::gpu;

namespace {

// Every value of a node is (texel scale) x (3 codebook scales) x (level-1 value) in all schemes:
// k > s: rgb scales, k <= s: lum scales, levels 4, 3, 2 each contribute one. Level-1 values are
// half already in the model, so half storage rounds 4 factors, each by a relative 2^-11 at most.
constexpr double k_half_rel = 4 * 0x1p-11 * 1.01;
// Float storage holds the model's values exactly; the remaining difference is float evaluation
// order (FMA contraction may differ between the model's and the emulation's code).
constexpr double k_float_rel = 2e-6;
// Grid coordinates of arbitrary directions in float (shader) instead of double (model): a few
// 1e-6 node units on each axis, times the value's change per node.
constexpr double k_coord_rel = 2e-5;

std::unique_ptr<Model> encode(const Btf& b, const std::string& spec) {
  auto s = parse_spec_string(spec);
  EXPECT_TRUE(s.ok()) << s.status().message();
  auto p = bind_params(*s, mlvq_codec().params());
  EXPECT_TRUE(p.ok()) << p.status().message();
  Context ctx;
  auto m = mlvq_codec().encode(b, *p, ctx);
  EXPECT_TRUE(m.ok()) << m.status().message();
  return m.ok() ? std::move(m).value() : nullptr;
}

Btf synth(int w, int h, float scale = 1, uint64_t seed = 5) {
  SynthOptions o;
  o.width = w, o.height = h, o.scale = scale, o.seed = seed;
  auto r = synthesize_btf(o);
  EXPECT_TRUE(r.ok()) << r.status().message();
  return std::move(r).value();
}

Btf grey(const Btf& b) {
  BtfDesc d = b.desc();
  d.channels = 1;
  auto g = Btf::create(d);
  EXPECT_TRUE(g.ok()) << g.status().message();
  const size_t n = g->size();
  for (size_t i = 0; i < n; ++i) g->data()[i] = (b.data()[3 * i] + b.data()[3 * i + 1] + b.data()[3 * i + 2]) / 3;
  return std::move(g).value();
}

// Models are expensive to encode: one per (BTF kind, scheme), shared by the tests.
const Model& model(const std::string& kind, int scheme) {
  static std::map<std::string, std::unique_ptr<Model>> cache;
  const std::string key = kind + std::to_string(scheme);
  auto& m = cache[key];
  if (!m) {
    const std::string spec = "mlvq:scheme=" + std::to_string(scheme) + ":phi=8:theta=4:alpha=7:beta=7";
    if (kind == "rgb") m = encode(synth(7, 5), spec);
    else if (kind == "grey") m = encode(grey(synth(5, 3, 1, 9)), spec);
    else m = encode(synth(3, 5, 1e6f, 11), spec);  // hdr: values up to ~1e6, 16-bit scales
  }
  return *m;
}

ExportBundle bundle(const Model& m, bool half) {
  ExportOptions o;
  o.half = half;
  auto b = build_export(m, o);
  EXPECT_TRUE(b.ok()) << b.status().message();
  return std::move(b).value();
}

float uv_of(int x, int n) { return (float(x) + 0.5f) / float(n); }

struct Err {
  double max_rel = 0, max_abs = 0;
  size_t n = 0;
};

// Per channel |e - m| / (|m| + floor), floor = 1e-4 of the largest |m| (the relative bound holds
// for non-negative node colours; the floor covers channels near zero), over n queries.
Err error_of(const std::vector<float>& ref, const std::vector<float>& emu, size_t n) {
  double mx = 0;
  for (float r : ref) mx = std::max(mx, double(std::fabs(r)));
  Err e;
  for (size_t i = 0; i < ref.size(); ++i) {
    const double a = std::fabs(double(emu[i]) - ref[i]);
    e.max_abs = std::max(e.max_abs, a);
    e.max_rel = std::max(e.max_rel, a / (std::fabs(ref[i]) + 1e-4 * mx));
  }
  e.n = n;
  return e;
}

// Emulation vs model at the measured directions, relative as error_of.
Err measured_error(const Model& m, const ExportBundle& b, int step) {
  const BtfDesc& d = m.desc();
  std::vector<float> ref, emu;
  for (int y = 0; y < d.height; ++y)
    for (int x = 0; x < d.width; ++x)
      for (int v = 0, k = 0; v < int(d.num_views()); ++v)
        for (int l = 0; l < int(d.num_lights()); ++l, ++k) {
          if (k % step != (x + y) % step) continue;
          float mv[3] = {0, 0, 0}, ev[3];
          m.eval(x, y, l, v, mv);
          ShaderQuery q;
          q.u = uv_of(x, d.width), q.v = uv_of(y, d.height), q.light = l, q.view = v;
          find_exporter("mlvq")->emulate(b, q, ev);
          for (int c = 0; c < 3; ++c) {
            if (c >= d.channels) {
              EXPECT_EQ(ev[c], 0.f) << "channel beyond a grey BTF's";
            }
            ref.push_back(c < d.channels ? mv[c] : 0.f), emu.push_back(c < d.channels ? ev[c] : 0.f);
          }
        }
  return error_of(ref, emu, ref.size() / 3);
}

Vec3 random_dir(std::mt19937& rng, float min_z) {
  std::uniform_real_distribution<float> u(-1, 1);
  for (;;) {
    const Vec3 d{u(rng), u(rng), u(rng)};
    const float n = std::sqrt(d.x * d.x + d.y * d.y + d.z * d.z);
    if (n > 0.1f && n <= 1 && d.z / n >= min_z) return {d.x / n, d.y / n, d.z / n};
  }
}

// Emulation vs eval_dir at random directions (plus the pole, a light on the horizon, lights below
// it): relative as above. Not exactly at beta = +-90 degrees (light on the horizon, perpendicular
// to the view plane): alpha is undefined there (atan2(~0, 0)), float and double pick opposite
// ends of the alpha axis, and the codebooks reconstruct the (resampled-identical) nodes of that
// pole with their own small differences.
Err direction_error(const Model& m, const ExportBundle& b, int count) {
  const BtfDesc& d = m.desc();
  std::mt19937 rng(42);
  std::vector<float> ref, emu;
  for (int i = 0; i < count; ++i) {
    const int x = i % d.width, y = (i / d.width) % d.height;
    Vec3 wl = random_dir(rng, -0.2f), wv = random_dir(rng, 0.f);
    if (i == 0) wv = {0, 0, 1};
    if (i == 1) wl = {0, 0, 1};
    if (i == 2) wl = {1, 0, 0}, wv = {0.6f, 0, 0.8f};
    float mv[3] = {0, 0, 0}, ev[3];
    EXPECT_TRUE(m.eval_dir(x, y, wl, wv, mv).ok());
    ShaderQuery q;
    q.u = uv_of(x, d.width), q.v = uv_of(y, d.height), q.wl = wl, q.wv = wv;
    find_exporter("mlvq")->emulate(b, q, ev);
    for (int c = 0; c < d.channels; ++c) ref.push_back(mv[c]), emu.push_back(ev[c]);
  }
  return error_of(ref, emu, size_t(count));
}

class MlvqExportScheme : public ::testing::TestWithParam<int> {};

TEST_P(MlvqExportScheme, FloatEmulationEqualsModel) {
  const Model& m = model("rgb", GetParam());
  const ExportBundle b = bundle(m, false);
  EXPECT_EQ(b.evaluation.at("scheme").get<int>(), GetParam());
  EXPECT_EQ(b.clamped(), 0u);
  for (const GpuTexture& t : b.textures) EXPECT_EQ(t.scale, 1.0) << t.name;
  const Err e = measured_error(m, b, 5);
  EXPECT_GT(e.n, 10000u);
  EXPECT_LE(e.max_rel, k_float_rel);
  // Arbitrary directions: the shader computes grid coordinates in float, the model in double.
  const Err f = direction_error(m, b, 400);
  EXPECT_LE(f.max_rel, k_coord_rel);
  std::printf("scheme %d float: measured max rel %.3g (abs %.3g, %zu queries), directions max rel %.3g (abs %.3g)\n", GetParam(),
              e.max_rel, e.max_abs, e.n, f.max_rel, f.max_abs);
}

TEST_P(MlvqExportScheme, HalfEmulationWithinHalfRounding) {
  const Model& m = model("rgb", GetParam());
  const ExportBundle b = bundle(m, true);
  EXPECT_EQ(b.clamped(), 0u);
  EXPECT_EQ(format_info(b.find("texel_scale")->format).name, std::string("r16f"));
  EXPECT_EQ(format_info(b.find("lum1")->format).name, std::string("r16f"));
  EXPECT_EQ(format_info(b.find("chroma1")->format).name, std::string("rg16f"));
  const Err e = measured_error(m, b, 5);
  // Upper: 4 half-rounded factors. Lower: one factor's rounding reaches 2^-11 relative (values just
  // above a power of two); the largest of thousands of sums of 4 such roundings exceeds that.
  EXPECT_LE(e.max_rel, k_half_rel);
  EXPECT_GE(e.max_rel, 0x1p-11);
  const Err f = direction_error(m, b, 400);
  EXPECT_LE(f.max_rel, k_half_rel + k_coord_rel);
  std::printf("scheme %d half: measured max rel %.3g (abs %.3g), directions max rel %.3g; textures %llu bytes, model %llu bytes\n",
              GetParam(), e.max_rel, e.max_abs, f.max_rel, (unsigned long long)b.texture_bytes(), (unsigned long long)b.model_payload_bytes);
}

TEST_P(MlvqExportScheme, GreyBtfFirstChannelOnly) {
  const Model& m = model("grey", GetParam());
  ASSERT_EQ(m.desc().channels, 1);
  const ExportBundle b = bundle(m, false);
  EXPECT_NE(b.glsl.find("vec3(r.x, 0.0, 0.0)"), std::string::npos);
  EXPECT_LE(measured_error(m, b, 7).max_rel, k_float_rel);
  const Err f = direction_error(m, b, 200);
  EXPECT_LE(f.max_rel, k_coord_rel);
  std::printf("grey scheme %d: directions max rel %.3g abs %.3g (%zu textures, model %llu bytes)\n", GetParam(), f.max_rel, f.max_abs,
              b.textures.size(), (unsigned long long)b.model_payload_bytes);
}

INSTANTIATE_TEST_SUITE_P(Schemes, MlvqExportScheme, ::testing::Values(1, 2, 3, 4));

TEST(MlvqExport, HdrScalesStayInHalfRange) {
  const Model& m = model("hdr", 2);
  const ExportBundle b = bundle(m, true);
  EXPECT_EQ(b.clamped(), 0u);
  // Texel scales of a 1e6 BTF exceed the half maximum: stored divided by a power of two.
  // The 1e6 range ends up in the codebook scales (the level-2 ones exceed the half maximum) and
  // the texel scales are small: every scale texture is stored divided by a power of two that
  // puts its maximum in [2^14, 2^15].
  double smax = 0;
  for (const GpuTexture& t : b.textures) {
    if (t.name.find("scale") == std::string::npos) continue;
    EXPECT_EQ(std::exp2(std::round(std::log2(t.scale))), t.scale) << t.name;
    float mx = 0;
    for (float x : t.f[0]) mx = std::max(mx, std::fabs(x));
    EXPECT_GE(mx, 16384.f) << t.name;
    EXPECT_LE(mx, 32768.f) << t.name;
    smax = std::max(smax, t.scale);
  }
  EXPECT_GT(smax, 1.0);
  const GpuTexture& ts = *b.find("texel_scale");
  const Err e = measured_error(m, b, 5);
  EXPECT_LE(e.max_rel, k_half_rel);
  EXPECT_GE(e.max_rel, 0x1p-11);
  std::printf("hdr half: largest texture scale %g, texel_scale scale %g, measured max rel %.3g (abs %.3g)\n", smax, ts.scale, e.max_rel, e.max_abs);
  // Clamping instead of scaling is reported.
  ExportOptions o;
  o.clamp_half = true;
  auto c = build_export(m, o);
  ASSERT_TRUE(c.ok());
  EXPECT_GT(c->clamped(), 0u);
  EXPECT_FALSE(c->warnings.empty());
}

TEST(MlvqExport, Ktx2RoundTripKeepsEveryValue) {
  const Model& m = model("rgb", 2);
  for (bool half : {true, false}) {
    const ExportBundle b = bundle(m, half);
    const std::string dir = ::testing::TempDir() + "mlvq_ktx2_" + std::to_string(::getpid()) + (half ? "h" : "f");
    std::filesystem::create_directories(dir);
    ExportBundle back = b;
    for (GpuTexture& t : back.textures) {
      const std::string path = dir + "/" + t.name + ".ktx2";
      ASSERT_TRUE(write_ktx2(t, path).ok());
      auto r = read_ktx2(path);
      ASSERT_TRUE(r.ok()) << r.status().message();
      EXPECT_EQ(r->format, t.format) << t.name;
      EXPECT_EQ(r->width, t.width);
      EXPECT_EQ(r->height, t.height);
      EXPECT_EQ(r->layers, t.layers);
      EXPECT_EQ(r->u, t.u) << t.name;
      EXPECT_EQ(r->f, t.f) << t.name;
      const std::string name = t.name;
      const double scale = t.scale;
      t = std::move(r).value();
      t.name = name, t.scale = scale;  // the manifest's, not the container's
    }
    std::filesystem::remove_all(dir);
    // The emulation from the read-back textures is bit-identical.
    for (int i = 0; i < 200; ++i) {
      ShaderQuery q;
      q.u = uv_of(i % 7, 7), q.v = uv_of(i % 5, 5), q.light = (i * 13) % 81, q.view = (i * 29) % 81;
      float a[3], c[3];
      find_exporter("mlvq")->emulate(b, q, a);
      find_exporter("mlvq")->emulate(back, q, c);
      for (int k = 0; k < 3; ++k) EXPECT_EQ(a[k], c[k]);
    }
  }
}

TEST(MlvqExport, LayoutAndShaderContract) {
  for (int scheme : {1, 4}) {
    const Model& m = model("rgb", scheme);
    const ExportBundle b = bundle(m, true);
    EXPECT_EQ(b.glsl.rfind("#version 300 es\n", 0), 0u);
    EXPECT_NE(b.glsl.find("#ifndef BTFC_NO_MAIN"), std::string::npos);
    EXPECT_NE(b.glsl.find("vec3 btf_eval(vec2 uv, vec3 wl, vec3 wv)"), std::string::npos);
    EXPECT_NE(b.glsl.find("vec3 btf_eval_measured(vec2 uv, int light, int view)"), std::string::npos);
    for (const GpuTexture& t : b.textures) {
      const std::string decl = std::string("uniform highp ") + (t.is_integer() ? "usampler2D" : "sampler2D") + " u_" + t.name + ";";
      EXPECT_NE(b.glsl.find(decl), std::string::npos) << decl;
      EXPECT_EQ(t.layers, 0u);
      EXPECT_LE(t.width, 2048u);
    }
    // Scheme 1 has rgb books at levels 4..2 and no lum / chroma books above level 1; scheme 4
    // the opposite. The texel map is W x H, the 4D index of scheme 4 points into the merge book.
    EXPECT_EQ(b.find("rgb2_index") != nullptr, scheme == 1);
    EXPECT_EQ(b.find("lum4_scale") != nullptr, scheme == 4);
    EXPECT_EQ(b.find("chroma2_index") != nullptr, scheme == 4);
    EXPECT_EQ(b.find("texel_index")->width, 7u);
    EXPECT_EQ(b.find("texel_index")->height, 5u);
    EXPECT_EQ(b.find("measured_coord")->width, 81u);
    const nlohmann::json man = manifest_json(b);
    EXPECT_EQ(man.at("codec"), "mlvq");
    EXPECT_EQ(man.at("evaluation").at("grid").at("nbeta"), 7);
    EXPECT_EQ(man.at("textures").size(), b.textures.size());
    // glslangValidator (glslang-tools), when installed, must accept the shader as GLSL ES 3.00.
    if (std::system("command -v glslangValidator >/dev/null 2>&1") == 0) {
      const std::string path = ::testing::TempDir() + "mlvq_" + std::to_string(::getpid()) + "_" + std::to_string(scheme) + ".frag";
      std::ofstream(path) << b.glsl;
      EXPECT_EQ(std::system(("glslangValidator -S frag " + path + " >/dev/null").c_str()), 0) << b.glsl;
      std::remove(path.c_str());
    }
  }
}

}  // namespace

// The measured layout (mlvq's default): nodes are measured pairs, so btf_eval_measured reads
// one node, and btf_eval blends the 3 x 3 measured pairs of the Delaunay direction maps
// (codecs/gpu_export.h) as the other codecs' exports do. Reference for directions: the model's
// own measured values blended with the bundle's map weights (the maps sample the model's
// interpolation at their cell centres, so that is what the shader can reproduce exactly).
TEST(MlvqExportMeasured, EmulationEqualsModelAtMeasuredPairsAndMapBlendAtDirections) {
  auto m = encode(synth(6, 5, 20, 3), "mlvq");
  ASSERT_TRUE(m);
  for (bool half : {false, true}) {
    const ExportBundle b = bundle(*m, half);
    EXPECT_EQ(b.evaluation.at("layout"), "measured");
    ASSERT_TRUE(b.find("dir_index") && b.find("dir_weight"));
    EXPECT_NE(b.glsl.find("mlvq_eval_dir"), std::string::npos);
    EXPECT_NE(b.glsl.find("usampler2DArray u_dir_index"), std::string::npos);
    const Err e = measured_error(*m, b, 3);
    EXPECT_LE(e.max_rel, half ? k_half_rel : k_float_rel) << half;
    const BtfDesc& d = m->desc();
    std::mt19937 rng(9);
    std::vector<float> ref, emu;
    for (int i = 0; i < 300; ++i) {
      const int x = i % d.width, y = (i / d.width) % d.height;
      const Vec3 wl = random_dir(rng, 0.05f), wv = random_dir(rng, 0.05f);
      float mv[3], ev[3];
      emulate_delaunay(b, wl, wv, [&](int l, int v, float* rgb) { m->eval(x, y, l, v, rgb); }, mv);
      ShaderQuery q;
      q.u = uv_of(x, d.width), q.v = uv_of(y, d.height), q.wl = wl, q.wv = wv;
      find_exporter("mlvq")->emulate(b, q, ev);
      for (int c = 0; c < 3; ++c) ref.push_back(mv[c]), emu.push_back(ev[c]);
    }
    const Err f = error_of(ref, emu, 300);
    EXPECT_LE(f.max_rel, half ? k_half_rel : k_float_rel) << half;
    std::printf("measured layout %s: measured max rel %.3g, directions max rel %.3g\n", half ? "half" : "float", e.max_rel, f.max_rel);
  }
}
