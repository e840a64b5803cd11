// The contract every registered codec keeps (codecs/codec.h, codecs/gpu_export.h,
// codecs/measure.h), checked for each entry of the registry, whatever its name: a new codec is
// tested here as soon as its registry line exists (the test-only codec tests/toy_codec is one).
//
// On a small synthetic BTF (4 x 4 texels, the 81 x 81 UBO2003 directions) with the codec's
// default spec: encode; decode shape and finiteness; eval and eval_dir at measured directions
// equal the decode; a region / direction-subset decode equals that part of the whole decode;
// save -> load decodes the same values bit for bit and saves the same bytes; model_file_bytes is
// the file's size; every truncation of the file is an error, never a crash; an unknown
// parameter is an error naming it; the GPU bundle's CPU emulation equals the model; the
// benchmark's numbers agree with the model.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "codecs/codec.h"
#include "codecs/gpu_export.h"
#include "codecs/measure.h"
#include "core/container.h"
#include "core/synth.h"

namespace btfc {
namespace {

std::vector<std::string> registered_names() {
  std::vector<std::string> names;
  for (const Codec* c : all_codecs()) names.push_back(c->name());
  return names;
}

const Btf& input() {
  static const Btf btf = [] {
    SynthOptions o;
    o.width = 4, o.height = 4, o.seed = 11;
    return synthesize_btf(o).value();
  }();
  return btf;
}

float peak(const Btf& b) {
  float m = 0;
  for (size_t i = 0; i < b.size(); ++i) m = std::max(m, std::abs(b.data()[i]));
  return m;
}

std::string temp_path(const std::string& name) {
  return (std::filesystem::temp_directory_path() / ("btfc-contract-" + std::to_string(::getpid()) + "-" + name)).string();
}

class CodecContract : public ::testing::TestWithParam<std::string> {
 protected:
  void SetUp() override {
    codec = find_codec(GetParam());
    ASSERT_NE(codec, nullptr);
    auto spec = resolve_spec(GetParam());
    ASSERT_TRUE(spec.ok()) << spec.status().message();
    Context ctx;
    auto m = codec->encode(input(), spec->second, ctx);
    ASSERT_TRUE(m.ok()) << m.status().message();
    model = std::move(m.value());
    ASSERT_TRUE(model->decode_all(decoded).ok());
  }
  const Codec* codec = nullptr;
  std::unique_ptr<Model> model;
  Btf decoded;
};

TEST_P(CodecContract, EncodeDecodeShapeAndAccuracy) {
  const BtfDesc& d = input().desc();
  EXPECT_EQ(model->spec().rfind(GetParam(), 0), 0u) << model->spec();
  EXPECT_EQ(model->desc().summary(), d.summary());
  ASSERT_EQ(decoded.size(), input().size());
  double err = 0, ref = 0;
  for (size_t i = 0; i < decoded.size(); ++i) {
    ASSERT_TRUE(std::isfinite(decoded.data()[i])) << i;
    const double e = double(decoded.data()[i]) - input().data()[i];
    err += e * e, ref += double(input().data()[i]) * input().data()[i];
  }
  // Any codec does better than "all zero" on a smooth synthetic material at its default.
  EXPECT_LT(std::sqrt(err / ref), 0.9);
  EXPECT_GT(model->payload_bytes(), 0u);
}

TEST_P(CodecContract, ValuesNearTheLargestFloatGiveAModelOrAClearError) {
  // Finite input whose sums pass the float range (the material scaled to a peak of 2.7e38):
  // either a model that decodes to finite values, or an error that says so; never a crash
  // (mlvq threw from its tensors) or a model of infinities and NaN (fmf, lpyr).
  Btf huge = input();
  const float s = 2.7e38f / peak(input());
  for (size_t i = 0; i < huge.size(); ++i) huge.data()[i] *= s;
  auto spec = resolve_spec(GetParam());
  ASSERT_TRUE(spec.ok());
  Context ctx;
  auto m = codec->encode(huge, spec->second, ctx);
  if (!m.ok()) {
    EXPECT_EQ(m.status().code(), StatusCode::unsupported) << m.status().message();
    EXPECT_NE(m.status().message().find("scale the BTF down"), std::string::npos) << m.status().message();
    return;
  }
  Btf out;
  ASSERT_TRUE(m.value()->decode_all(out).ok());
  size_t bad = 0;
  for (size_t i = 0; i < out.size(); ++i) bad += !std::isfinite(out.data()[i]);
  EXPECT_EQ(bad, 0u) << "of " << out.size();
}

TEST_P(CodecContract, EvalAndEvalDirAgreeWithDecode) {
  const BtfDesc& d = input().desc();
  const float tol = 1e-4f * peak(input());
  const int ch = d.channels;
  std::vector<float> v(static_cast<size_t>(ch)), w(static_cast<size_t>(ch));
  for (int y = 0; y < d.height; y += 3)
    for (int x = 0; x < d.width; x += 2)
      for (size_t l : {size_t(0), size_t(17), d.num_lights() - 1})
        for (size_t vi : {size_t(0), size_t(40), d.num_views() - 1}) {
          model->eval(x, y, int(l), int(vi), v.data());
          ASSERT_TRUE(model->eval_dir(x, y, d.lights.dirs[l], d.views.dirs[vi], w.data()).ok());
          for (int c = 0; c < ch; ++c) {
            const float ref = decoded.at(size_t(x), size_t(y), l, vi, size_t(c));
            EXPECT_NEAR(v[size_t(c)], ref, tol) << x << "," << y << " l" << l << " v" << vi;
            EXPECT_NEAR(w[size_t(c)], ref, tol) << "eval_dir " << x << "," << y << " l" << l << " v" << vi;
          }
        }
  float out[4];
  EXPECT_FALSE(model->eval_dir(d.width, 0, d.lights.dirs[0], d.views.dirs[0], out).ok());
}

TEST_P(CodecContract, RegionDecodeIsPartOfTheWholeDecode) {
  DecodeRequest r;
  r.x0 = 1, r.y0 = 2, r.width = 2, r.height = 2, r.lights = {3, 0, 50}, r.views = {80, 7};
  Btf part;
  ASSERT_TRUE(model->decode(r, part).ok());
  ASSERT_EQ(part.desc().width, 2);
  ASSERT_EQ(part.desc().num_lights(), 3u);
  const float tol = 1e-5f * peak(input());
  for (int y = 0; y < 2; ++y)
    for (int x = 0; x < 2; ++x)
      for (size_t l = 0; l < 3; ++l)
        for (size_t v = 0; v < 2; ++v)
          for (size_t c = 0; c < 3; ++c)
            EXPECT_NEAR(part.at(size_t(x), size_t(y), l, v, c),
                        decoded.at(size_t(x + 1), size_t(y + 2), size_t(r.lights[l]), size_t(r.views[v]), c), tol);
  DecodeRequest bad;
  bad.x0 = 3, bad.width = 4;
  EXPECT_FALSE(model->decode(bad, part).ok());
}

TEST_P(CodecContract, SaveLoadIsExactAndStable) {
  const std::string p1 = temp_path(GetParam() + "-1.btfc"), p2 = temp_path(GetParam() + "-2.btfc");
  ASSERT_TRUE(save_model(*model, *codec, p1).ok());
  auto bytes = model_file_bytes(*model, *codec);
  ASSERT_TRUE(bytes.ok());
  EXPECT_EQ(*bytes, std::filesystem::file_size(p1));
  auto rd = ContainerReader::open(p1);
  ASSERT_TRUE(rd.ok()) << rd.status().message();
  auto back = load_model(*rd);
  ASSERT_TRUE(back.ok()) << back.status().message();
  EXPECT_EQ((*back)->spec(), model->spec());
  Btf again;
  ASSERT_TRUE((*back)->decode_all(again).ok());
  ASSERT_EQ(again.size(), decoded.size());
  EXPECT_EQ(0, std::memcmp(again.data(), decoded.data(), decoded.size() * sizeof(float)));
  // Saved again, the tensors are the same bytes (the STAT chunk holds encode statistics, such as
  // timings, that a loaded model does not have: it is not part of the model).
  ASSERT_TRUE(save_model(**back, *codec, p2).ok());
  EXPECT_EQ(model_digest(**back), model_digest(*model));
  auto r2 = ContainerReader::open(p2);
  ASSERT_TRUE(r2.ok());
  ASSERT_EQ(r2->tensors().size(), rd->tensors().size());
  for (const TensorInfo& t : rd->tensors()) {
    auto x = rd->read(t.name), y = r2->read(t.name);
    ASSERT_TRUE(x.ok() && y.ok()) << t.name;
    EXPECT_TRUE(x->bytes == y->bytes && x->shape == y->shape && x->dtype == y->dtype) << t.name << " changed on save -> load -> save";
  }
  std::remove(p1.c_str());
  std::remove(p2.c_str());
}

TEST_P(CodecContract, TruncatedFilesAreErrors) {
  const std::string p = temp_path(GetParam() + "-t.btfc"), q = temp_path(GetParam() + "-cut.btfc");
  ASSERT_TRUE(save_model(*model, *codec, p).ok());
  std::ifstream f(p, std::ios::binary);
  const std::string all((std::istreambuf_iterator<char>(f)), {});
  const size_t n = all.size();
  for (size_t k = 0; k < 24; ++k) {
    const size_t cut = k < 23 ? n * k / 23 : n - 1;
    std::ofstream(q, std::ios::binary | std::ios::trunc).write(all.data(), std::streamsize(cut));
    auto rd = ContainerReader::open(q);
    if (rd.ok()) {
      auto m = load_model(*rd);
      EXPECT_FALSE(m.ok()) << "a " << cut << "-byte prefix of " << n << " bytes loaded";
    } else {
      EXPECT_NE(rd.status().message().find(q), std::string::npos) << rd.status().message();
    }
  }
  std::remove(p.c_str());
  std::remove(q.c_str());
}

TEST_P(CodecContract, UnknownParameterIsAnError) {
  auto r = resolve_spec(GetParam() + ":no_such_key=1");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::invalid_argument);
  EXPECT_NE(r.status().message().find("no_such_key"), std::string::npos) << r.status().message();
}

TEST_P(CodecContract, GpuBundleEmulationEqualsTheModel) {
  const gpu::Exporter* ex = gpu::find_exporter(GetParam());
  if (!ex) GTEST_SKIP() << GetParam() << " has no GPU exporter (its registry entry names none)";
  gpu::ExportOptions opt;
  opt.half = false;  // float textures: the emulation must then equal the model to float rounding
  auto b = gpu::build_export(*model, opt);
  ASSERT_TRUE(b.ok()) << b.status().message();
  EXPECT_FALSE(b->textures.empty());
  EXPECT_EQ(b->glsl.rfind("#version 300 es", 0), 0u);
  const BtfDesc& d = input().desc();
  const float tol = 1e-3f * peak(input());
  for (int y = 0; y < d.height; y += 3)
    for (int x = 0; x < d.width; x += 3)
      for (int l : {0, 33})
        for (int v : {0, 80}) {
          gpu::ShaderQuery q;
          q.u = (x + 0.5f) / float(d.width), q.v = (y + 0.5f) / float(d.height), q.light = l, q.view = v;
          float rgb[3], ref[3];
          ex->emulate(*b, q, rgb);
          model->eval(x, y, l, v, ref);
          for (int c = 0; c < 3; ++c) EXPECT_NEAR(rgb[c], ref[c], tol) << x << "," << y << " l" << l << " v" << v;
        }
}

TEST_P(CodecContract, BenchmarkMeasuresTheModel) {
  BenchOptions opt;
  opt.throughput_queries = 256, opt.throughput_seconds = 0, opt.renders = false;
  auto r = run_benchmark(input(), GetParam(), opt);
  ASSERT_TRUE(r.ok()) << r.status().message();
  EXPECT_EQ(r->spec, model->spec());
  EXPECT_EQ(r->payload_bytes, model->payload_bytes());
  EXPECT_NEAR(r->ratio, double(input().size() * sizeof(float)) / double(r->payload_bytes), 1e-9 * r->ratio);
  EXPECT_GT(r->metrics.psnr, 0);
  EXPECT_GT(r->evals_per_second, 0);
  EXPECT_EQ(r->tensor_digest, model_digest(*model));  // deterministic: the same spec, the same model
}

INSTANTIATE_TEST_SUITE_P(Registered, CodecContract, ::testing::ValuesIn(registered_names()),
                         [](const ::testing::TestParamInfo<std::string>& i) { return i.param; });

TEST(Registry, TheTestOnlyCodecIsRegisteredByOneLine) {
  // tests/toy_codec/register.cpp's one line put it after the library's own table.
  ASSERT_NE(find_codec("toy"), nullptr);
  EXPECT_EQ(std::string(all_codecs().back()->name()), "toy");
  EXPECT_NE(gpu::find_exporter("toy"), nullptr);
  size_t n = 0;
  for (const CodecEntry& e : codec_registry()) n += std::string(e.codec->name()) == "toy";
  EXPECT_EQ(n, 1u);
}

}  // namespace
}  // namespace btfc
