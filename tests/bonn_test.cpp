// Tests of the Bonn .btf readers and writers (formats/bonn/bonn_btf.h, formats.md 2.2).
// Files are built by an independent byte-level helper (FileBuilder) straight from the
// documented layout, not by the library's writer, so reader and writer cannot share a mistake.
#include <bzlib.h>
#include <gtest/gtest.h>

#include <Imath/half.h>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include "codecs/codec.h"
#include "codecs/fmf/fmf.h"
#include "core/container.h"
#include "core/synth.h"
#include "formats/bonn/bonn_btf.h"
#include "tests/codec_test_util.h"

using namespace btfc;

namespace {

using test::encode_spec;

std::string tmp_path(const std::string& name) {
  return std::string(::testing::TempDir()) + "bonn_" + std::to_string(::getpid()) + "_" + name;
}

BtfDesc small_desc(int w, int h, int nl, int nv) {
  BtfDesc d;
  d.width = w, d.height = h;
  for (int i = 0; i < nl; ++i) d.lights.dirs.push_back(dir_from_theta_phi(0.1 + 0.12 * (i % 7), 0.9 * i + 0.1));
  for (int i = 0; i < nv; ++i) d.views.dirs.push_back(dir_from_theta_phi(0.2 + 0.15 * (i % 5), 1.3 * i + 0.2));
  d.lights.name = d.views.name = "custom";
  return d;
}

// Little-endian byte builder following formats.md 2.2 field by field.
struct FileBuilder {
  std::vector<uint8_t> b;
  void raw(const void* p, size_t n) { b.insert(b.end(), (const uint8_t*)p, (const uint8_t*)p + n); }
  void str(const char* s) { raw(s, std::strlen(s)); }
  void u8(uint8_t v) { b.push_back(v); }
  void u32(uint32_t v) { raw(&v, 4); }
  void i32(int32_t v) { raw(&v, 4); }
  void f32(float v) { raw(&v, 4); }
  void half(float v) {
    uint16_t h = Imath::half(v).bits();
    raw(&h, 2);
  }
  void scalar(float v, int ss) {
    if (ss == 2) half(v);
    else if (ss == 4) f32(v);
    else {
      double d = v;
      raw(&d, 8);
    }
  }
  // Meta block of the given version; struct_size counts from its own first byte.
  void meta(uint32_t version, int channels = 3, int32_t size_delta = 0) {
    FileBuilder m;
    m.u32(version);
    char text[80] = {0};
    std::strcpy(text, "test setup");
    m.raw(text, 80);
    std::memset(text, 0, 80);
    m.raw(text, 80);
    m.raw(text, 80);
    m.f32(10.0f);
    for (int i = 0; i < 3; ++i) m.f32(1.0f);
    if (version > 1) m.u32(1);
    if (version > 2) {
      m.u32(5);
      m.str("<x/> ");
    }
    if (version > 3) {
      m.u32(uint32_t(channels));
      static const char* rgb[] = {"R", "G", "B"};
      for (int c = 0; c < channels; ++c) {
        std::string n = channels == 3 ? rgb[c] : std::to_string(400 + 10 * c);
        m.u32(uint32_t(n.size()));
        m.str(n.c_str());
      }
    }
    u32(uint32_t(int32_t(m.b.size() + 4) + size_delta));
    raw(m.b.data(), m.b.size());
  }
  void sampling(const BtfDesc& d, bool perturb_view1 = false) {
    u32(uint32_t(d.num_views()));
    for (size_t v = 0; v < d.num_views(); ++v) {
      double t, p;
      dir_to_theta_phi(d.views.dirs[v], t, p);
      f32(float(t)), f32(float(p));
      u32(uint32_t(d.num_lights()));
      for (size_t l = 0; l < d.num_lights(); ++l) {
        dir_to_theta_phi(d.lights.dirs[l], t, p);
        f32(float(t) + (perturb_view1 && v == 1 && l == 0 ? 0.01f : 0.0f)), f32(float(p));
      }
    }
  }
  void common(const char* sig, const BtfDesc& d, uint32_t meta_version = 4, int rotations = 0) {
    str(sig);
    meta(meta_version, d.channels);
    sampling(d);
    u32(uint32_t(d.width)), u32(uint32_t(d.height));
    if (sig[std::strlen(sig) - 1] == 'R') {
      u32(uint32_t(rotations));
      for (int i = 0; i < rotations * 9; ++i) f32(float(i % 9 == i / 9));
    }
  }
  void save(const std::string& path) const {
    std::ofstream f(path, std::ios::binary);
    f.write((const char*)b.data(), std::streamsize(b.size()));
  }
};

// A hand-built DFMF: per channel c, U_c[r][k] and SxV_c[t][k] from fixed formulas.
struct DfmfSpec {
  int cm = 11;
  int C[3] = {2, 1, 1};
  int ss = 4;
  float mean[3] = {0.1f, 0.2f, 0.3f};
  float T[3][3] = {{0.5f, 0.1f, 0.0f}, {0.2f, 0.7f, 0.1f}, {0.0f, 0.3f, 0.9f}};
};
float dfmf_u(int c, size_t r, int k) { return 0.1f * float(c + 1) + 0.01f * float(r % 13) - 0.05f * float(k); }
float dfmf_sxv(int c, size_t t, int k) { return 0.3f - 0.02f * float(t % 11) + 0.1f * float(k) - 0.05f * float(c); }

std::vector<uint8_t> build_dfmf(const BtfDesc& d, const DfmfSpec& s) {
  FileBuilder f;
  f.common("!DFMF08FCR", d, 4, 1);
  f.u32(uint32_t(std::max({s.C[0], s.C[1], s.C[2]})));
  f.i32(s.cm);
  for (float m : s.mean) f.f32(m);
  for (auto& row : s.T)
    for (float v : row) f.f32(v);
  for (int c = 0; c < 3; ++c) {
    f.u8(uint8_t(s.ss));
    f.u32(uint32_t(s.C[c]));
    f.u32(uint32_t(d.num_images()));
    f.u32(uint32_t(d.num_texels()));
    for (int k = 0; k < s.C[c]; ++k) f.scalar(10.0f - float(k), s.ss);
    for (size_t r = 0; r < d.num_images(); ++r)
      for (int k = 0; k < s.C[c]; ++k) f.scalar(dfmf_u(c, r, k), s.ss);
    for (size_t t = 0; t < d.num_texels(); ++t)
      for (int k = 0; k < s.C[c]; ++k) f.scalar(dfmf_sxv(c, t, k), s.ss);
  }
  return f.b;
}

// The colour-model formulas of formats.md 2.2 / BTFLIB undecorrelate.m, written out independently.
void expected_rgb(const DfmfSpec& s, const float* v, float* rgb) {
  const double eps = 1e-5;
  const double yuv2rgb[3][3] = {{1, 0, 1.13983}, {1, -0.39465, -0.5806}, {1, 2.03211, 0}};
  const double ycocg[3][3] = {{1, 1, -1}, {1, 0, 1}, {1, -1, -1}};
  double a[3] = {v[0], v[1], v[2]}, o[3] = {0, 0, 0};
  auto mul = [&](const double M[3][3]) {
    for (int i = 0; i < 3; ++i) o[i] = M[i][0] * a[0] + M[i][1] * a[1] + M[i][2] * a[2];
  };
  auto sgn = [](double x) { return x > 0 ? 1.0 : x < 0 ? -1.0 : 0.0; };
  switch (s.cm) {
    case 0: for (int i = 0; i < 3; ++i) o[i] = a[i]; break;
    case 1: mul(yuv2rgb); break;
    case 3:
      for (int j = 0; j < 3; ++j) o[j] = a[0] * s.T[0][j] + a[1] * s.T[1][j] + a[2] * s.T[2][j] + s.mean[j];
      break;
    case 4: mul(ycocg); break;
    case 9: a[0] = std::exp(a[0]) - eps; mul(yuv2rgb); break;
    case 10:
      a[0] = std::exp(a[0]) - eps;
      for (int i = 1; i < 3; ++i) a[i] = sgn(a[i]) * std::exp(std::fabs(a[i]) + std::log(eps));
      mul(yuv2rgb);
      break;
    case 11:
      a[0] = std::exp(a[0]) - eps;
      a[1] *= a[0] + eps, a[2] *= a[0] + eps;
      mul(yuv2rgb);
      break;
    case 12: for (int i = 0; i < 3; ++i) o[i] = std::exp(a[i]) - eps; break;
  }
  for (int i = 0; i < 3; ++i) rgb[i] = float(o[i]);
}

Btf synth(int w, int h, int nl, int nv) {
  SynthOptions o;
  o.width = w, o.height = h;
  const BtfDesc d = small_desc(w, h, nl, nv);
  o.lights = d.lights, o.views = d.views;
  return synthesize_btf(o).value();
}

Btf decode_all(const Model& m) {
  Btf out;
  Status s = m.decode_all(out);
  EXPECT_TRUE(s.ok()) << s.message();
  return out;
}

// max |a - b| / (tol_abs + tol_rel |a|) over all values.
double worst(const Btf& a, const Btf& b, double tol_abs, double tol_rel) {
  EXPECT_EQ(a.size(), b.size());
  double w = 0;
  for (size_t i = 0; i < a.size() && i < b.size(); ++i) w = std::max(w, std::fabs(double(a.data()[i]) - b.data()[i]) / (tol_abs + tol_rel * std::fabs(a.data()[i])));
  return w;
}

std::unique_ptr<Model> open_ok(const std::string& path, BonnInfo* info = nullptr) {
  auto m = open_bonn_model(path, info);
  EXPECT_TRUE(m.ok()) << m.status().message();
  return m.ok() ? std::move(m).value() : nullptr;
}

Status open_status(const std::string& path) {
  auto m = open_bonn_model(path);
  if (!m.ok()) return m.status();
  Btf out;
  return (*m)->decode_all(out);
}

}  // namespace

// ---- round trips: btfc fmf model -> writer -> reader ----

TEST(Bonn, DfmfRoundTripFloatIsExact) {
  const Btf btf = synth(6, 5, 9, 4);
  auto model = encode_spec(btf, "fmf:color=dfmf:rank=5:chroma_rank=3:precision=float:offset=1e-5");
  const std::string p = tmp_path("rt_float.btf");
  ASSERT_TRUE(write_bonn_dfmf(*model, p, false).ok());
  BonnInfo info;
  auto back = open_ok(p, &info);
  ASSERT_TRUE(back);
  EXPECT_EQ(info.kind, BonnKind::dfmf);
  EXPECT_EQ(info.color_model, 11);
  EXPECT_EQ(info.components, (std::vector<int>{5, 3, 3}));
  EXPECT_EQ(back->desc().width, 6);
  EXPECT_EQ(back->desc().num_lights(), 9u);
  for (size_t i = 0; i < 9; ++i) EXPECT_NEAR(back->desc().lights.dirs[i].z, btf.desc().lights.dirs[i].z, 1e-6);
  EXPECT_LE(worst(decode_all(*model), decode_all(*back), 1e-7, 1e-6), 1.0);
  std::remove(p.c_str());
}

TEST(Bonn, DfmfRoundTripHalfWithinHalfPrecision) {
  const Btf btf = synth(6, 5, 9, 4);
  auto model = encode_spec(btf, "fmf:color=dfmf:rank=4:precision=half:offset=1e-5");
  const std::string p = tmp_path("rt_half.btf");
  ASSERT_TRUE(write_bonn_dfmf(*model, p, true).ok());
  auto back = open_ok(p);
  ASSERT_TRUE(back);
  // Factors agree within one half rounding.
  auto a = fmf_factors(*model), b = fmf_factors(*back);
  ASSERT_TRUE(a.ok() && b.ok());
  ASSERT_EQ(a->blocks.size(), 3u);
  for (size_t k = 0; k < 3; ++k) {
    const FmfBlockView &x = a->blocks[k], &y = b->blocks[k];
    ASSERT_EQ(x.C, y.C);
    for (size_t i = 0; i < x.rows * size_t(x.C); ++i) EXPECT_NEAR(x.U[i], y.U[i], std::fabs(x.U[i]) * 1e-3 + 1e-7);
    for (size_t i = 0; i < x.texels * size_t(x.C); ++i) EXPECT_NEAR(x.SxV[i], y.SxV[i], std::fabs(x.SxV[i]) * 1e-3 + 1e-7);
  }
  // Decoded values: log-luminance model amplifies the 2^-11 rounding a little.
  EXPECT_LE(worst(decode_all(*model), decode_all(*back), 1e-3, 2e-2), 1.0);
  std::remove(p.c_str());
}

TEST(Bonn, FmfRoundTripRgbFloatAndHalf) {
  const Btf btf = synth(5, 4, 7, 3);
  auto model = encode_spec(btf, "fmf:rank=6:precision=float");
  for (bool half : {false, true}) {
    const std::string p = tmp_path(half ? "fmf_h.btf" : "fmf_f.btf");
    ASSERT_TRUE(write_bonn_fmf(*model, p, half).ok());
    BonnInfo info;
    auto back = open_ok(p, &info);
    ASSERT_TRUE(back);
    EXPECT_EQ(info.signature, "!FMF12FCER");
    EXPECT_EQ(info.scalar_sizes[0], half ? 2 : 4);
    EXPECT_LE(worst(decode_all(*model), decode_all(*back), half ? 2e-3 : 1e-7, half ? 1e-2 : 1e-6), 1.0);
    // float: bit-identical values through eval
    if (!half) {
      float x[3], y[3];
      model->eval(2, 3, 4, 1, x);
      back->eval(2, 3, 4, 1, y);
      for (int c = 0; c < 3; ++c) EXPECT_EQ(x[c], y[c]);
    }
    std::remove(p.c_str());
  }
}

TEST(Bonn, RgbModelWritesAsDfmfColourModel0AndBackAsFmf) {
  const Btf btf = synth(4, 4, 6, 2);
  auto model = encode_spec(btf, "fmf:rank=5:precision=float");
  const std::string p = tmp_path("cm0.btf"), q = tmp_path("cm0_fmf.btf");
  ASSERT_TRUE(write_bonn_dfmf(*model, p, false).ok());
  BonnInfo info;
  auto back = open_ok(p, &info);
  ASSERT_TRUE(back);
  EXPECT_EQ(info.color_model, 0);
  EXPECT_LE(worst(decode_all(*model), decode_all(*back), 1e-6, 1e-5), 1.0);
  // A colour model 0 DFMF merges exactly into one FMF block of C = 15.
  ASSERT_TRUE(write_bonn_fmf(*back, q, false).ok());
  auto again = open_ok(q, &info);
  ASSERT_TRUE(again);
  EXPECT_EQ(info.components[0], 15);
  EXPECT_LE(worst(decode_all(*model), decode_all(*again), 1e-6, 1e-5), 1.0);
  std::remove(p.c_str());
  std::remove(q.c_str());
}

TEST(Bonn, DfmfModelSavesToBtfcAndLoadsBack) {
  const BtfDesc d = small_desc(3, 2, 4, 2);
  DfmfSpec s;
  s.ss = 2;
  const std::string p = tmp_path("tobtfc.btf"), q = tmp_path("tobtfc.btfc");
  FileBuilder f;
  f.b = build_dfmf(d, s);
  f.save(p);
  auto m = open_ok(p);
  ASSERT_TRUE(m);
  EXPECT_NE(m->spec().find("color=dfmf"), std::string::npos);
  ASSERT_TRUE(save_model(*m, fmf_codec(), q).ok());
  auto rd = ContainerReader::open(q);
  ASSERT_TRUE(rd.ok());
  auto loaded = load_model(*rd);
  ASSERT_TRUE(loaded.ok()) << loaded.status().message();
  EXPECT_EQ(worst(decode_all(*m), decode_all(**loaded), 1e-9, 0), 0.0);  // half factors stored exactly
  // A non-native colour model decodes but refuses to become a .btfc.
  s.cm = 4;
  f.b = build_dfmf(d, s);
  f.save(p);
  auto m4 = open_ok(p);
  ASSERT_TRUE(m4);
  EXPECT_EQ(save_model(*m4, fmf_codec(), q + "4").code(), StatusCode::unsupported);
  std::remove(p.c_str());
  std::remove(q.c_str());
}

// ---- colour models, from hand-built files ----

TEST(Bonn, EveryColourModelDecodesPerItsFormula) {
  const BtfDesc d = small_desc(3, 2, 4, 2);
  for (int cm : {0, 1, 3, 4, 9, 10, 11, 12}) {
    for (int ss : {2, 4, 8}) {
      DfmfSpec s;
      s.cm = cm, s.ss = ss;
      const std::string p = tmp_path("cm" + std::to_string(cm) + ".btf");
      FileBuilder f;
      f.b = build_dfmf(d, s);
      f.save(p);
      auto m = open_ok(p);
      ASSERT_TRUE(m) << cm;
      const Btf out = decode_all(*m);
      for (size_t t = 0; t < d.num_texels(); ++t)
        for (size_t r = 0; r < d.num_images(); ++r) {
          float v[3], rgb[3];
          for (int c = 0; c < 3; ++c) {
            double acc = 0;
            for (int k = 0; k < s.C[c]; ++k) {
              auto q = [&](float x) { return ss == 2 ? float(Imath::half(x)) : x; };
              acc += double(q(dfmf_u(c, r, k))) * q(dfmf_sxv(c, t, k));
            }
            v[c] = float(acc);
          }
          expected_rgb(s, v, rgb);
          for (int c = 0; c < 3; ++c)
            ASSERT_NEAR(out.abrdf(t)[3 * r + size_t(c)], rgb[c], 1e-5 + 1e-5 * std::fabs(rgb[c])) << "model " << cm << " ss " << ss;
          float e[3];
          m->eval(int(t % 3), int(t / 3), int(r % 4), int(r / 4), e);
          for (int c = 0; c < 3; ++c) ASSERT_NEAR(e[c], rgb[c], 1e-5 + 1e-5 * std::fabs(rgb[c]));
        }
      std::remove(p.c_str());
    }
  }
}

TEST(Bonn, UnsupportedColourModelsSayWhich) {
  const BtfDesc d = small_desc(2, 2, 3, 2);
  for (int cm : {2, 5, 6, 7}) {
    DfmfSpec s;
    s.cm = cm;
    const std::string p = tmp_path("bad_cm.btf");
    FileBuilder f;
    f.b = build_dfmf(d, s);
    f.save(p);
    auto m = open_bonn_model(p);
    ASSERT_FALSE(m.ok());
    EXPECT_EQ(m.status().code(), StatusCode::unsupported);
    EXPECT_NE(m.status().message().find("colour model " + std::to_string(cm)), std::string::npos) << m.status().message();
    EXPECT_TRUE(read_bonn_info(p).ok());  // the structure itself is fine
    std::remove(p.c_str());
  }
}

TEST(Bonn, MetaVersionsAndDome1Identification) {
  BtfDesc d = small_desc(2, 2, 1, 1);
  d.lights = DirectionSet::ubo2014();
  d.views = DirectionSet::ubo2014();
  for (uint32_t ver : {1u, 2u, 3u, 4u}) {
    FileBuilder f;
    f.str("!FMF06FC");
    f.meta(ver);
    f.sampling(d);
    f.u32(2), f.u32(2);
    f.u32(1), f.u8(2), f.u32(1), f.u32(uint32_t(d.abrdf_size())), f.u32(4);
    f.half(1);
    for (size_t r = 0; r < d.abrdf_size(); ++r) f.half(0.5f);
    for (int t = 0; t < 4; ++t) f.half(float(t));
    const std::string p = tmp_path("dome.btf");
    f.save(p);
    BonnInfo info;
    auto m = open_ok(p, &info);
    ASSERT_TRUE(m);
    EXPECT_EQ(info.meta.struct_version, ver);
    EXPECT_EQ(info.meta.measurement_setup, "test setup");
    EXPECT_TRUE(info.dome1);
    EXPECT_LT(info.dome1_max_dev_deg, 1e-3);
    EXPECT_EQ(m->desc().lights.name, "ubo2014");
    float v[3];
    m->eval(1, 1, 150, 150, v);
    EXPECT_FLOAT_EQ(v[2], 1.5f);
    std::remove(p.c_str());
  }
}

// ---- PVF and BDI written by the helper ----

TEST(Bonn, PvfBothLayoutsDecode) {
  const BtfDesc d = small_desc(3, 2, 4, 2);
  const size_t nc = 3, nl = 4, T = 6;
  for (bool images : {false, true}) {
    FileBuilder f;
    f.common("!PVF06FCR", d);
    f.u32(2), f.u32(2);
    const size_t dim = images ? nc * T : nc * nl, nw = images ? nl : T;
    auto M = [](size_t v, size_t i) { return 0.01f * float(i) + float(v); };
    auto Cm = [](size_t v, size_t i, int k) { return 0.1f * float(k + 1) - 0.02f * float(i % 5) + 0.3f * float(v); };
    auto W = [](size_t v, size_t i, int k) { return 0.5f + 0.1f * float(i) - 0.2f * float(k) + 0.1f * float(v); };
    for (size_t v = 0; v < 2; ++v) {
      f.u8(4), f.u32(2), f.u32(uint32_t(nw)), f.u32(uint32_t(dim));
      f.f32(3), f.f32(1);
      for (size_t i = 0; i < dim; ++i) f.f32(M(v, i));
      for (size_t i = 0; i < dim; ++i)
        for (int k = 0; k < 2; ++k) f.f32(Cm(v, i, k));
      for (size_t i = 0; i < nw; ++i)
        for (int k = 0; k < 2; ++k) f.f32(W(v, i, k));
    }
    const std::string p = tmp_path("pvf.btf");
    f.save(p);
    auto m = open_ok(p);
    ASSERT_TRUE(m);
    const Btf out = decode_all(*m);
    for (size_t t = 0; t < T; ++t)
      for (size_t v = 0; v < 2; ++v)
        for (size_t l = 0; l < nl; ++l)
          for (size_t c = 0; c < nc; ++c) {
            const size_t mr = images ? c + nc * t : c + nc * l, wr = images ? l : t;
            const float e = M(v, mr) + Cm(v, mr, 0) * W(v, wr, 0) + Cm(v, mr, 1) * W(v, wr, 1);
            ASSERT_NEAR(out.abrdf(t)[d.row(l, v, c)], e, 1e-5);
          }
    std::remove(p.c_str());
  }
}

namespace {
// BDI: value of texel t, row r (any pattern, exact in half).
float bdi_value(size_t t, size_t r) { return float(int(t * 7 + r * 3) % 64) / 8.0f; }

std::vector<uint8_t> build_bdi(const BtfDesc& d, int compression, uint32_t spl, const std::vector<uint8_t>& mask) {
  FileBuilder f;
  f.str("!BDIF06R2!");
  f.meta(4, d.channels);
  f.sampling(d);
  f.u32(uint32_t(d.width)), f.u32(uint32_t(d.height)), f.u32(spl);
  f.u8(uint8_t(compression));
  f.raw(mask.data(), mask.size());
  f.u32(1);
  for (int i = 0; i < 9; ++i) f.f32(float(i % 4 == 0));
  std::vector<size_t> stored;
  for (size_t t = 0; t < d.num_texels(); ++t)
    if (compression != 2 || mask[t]) stored.push_back(t);
  const size_t per = size_t(d.width) * spl;
  for (size_t c0 = 0; c0 < stored.size(); c0 += per) {
    FileBuilder chunk;
    for (size_t i = c0; i < std::min(stored.size(), c0 + per); ++i)
      for (size_t r = 0; r < d.abrdf_size(); ++r) chunk.half(bdi_value(stored[i], r));
    if (compression == 1) {
      std::vector<char> comp(chunk.b.size() * 2 + 600);
      unsigned n = unsigned(comp.size());
      EXPECT_EQ(BZ2_bzBuffToBuffCompress(comp.data(), &n, (char*)chunk.b.data(), unsigned(chunk.b.size()), 9, 0, 0), BZ_OK);
      f.u32(n);
      f.raw(comp.data(), n);
    } else {
      f.u32(uint32_t(chunk.b.size()));
      f.raw(chunk.b.data(), chunk.b.size());
    }
  }
  return f.b;
}
}  // namespace

TEST(Bonn, BdiUncompressedSparseAndBzip2Decode) {
  const BtfDesc d = small_desc(5, 3, 4, 2);
  std::vector<uint8_t> mask(15, 1);
  for (int comp : {0, 1, 2}) {
    if (comp == 2) mask[1] = mask[7] = mask[14] = 0;
    FileBuilder f;
    f.b = build_bdi(d, comp, 1, mask);  // 1 scan line per chunk: several chunks, a short last one when sparse
    const std::string p = tmp_path("bdi.btf");
    f.save(p);
    BonnInfo info;
    auto m = open_ok(p, &info);
    ASSERT_TRUE(m);
    EXPECT_EQ(info.bdi_compression, comp);
    EXPECT_EQ(info.rotations.size(), 1u);
    const Btf out = decode_all(*m);
    for (size_t t = 0; t < 15; ++t)
      for (size_t r = 0; r < d.abrdf_size(); ++r)
        ASSERT_EQ(out.abrdf(t)[r], (comp == 2 && !mask[t]) ? 0.0f : bdi_value(t, r)) << comp << " " << t << " " << r;
    // Region decode and eval / eval_dir at a measured direction agree with the full decode.
    DecodeRequest req;
    req.x0 = 1, req.y0 = 1, req.width = 3, req.height = 2, req.lights = {2}, req.views = {1};
    Btf part;
    ASSERT_TRUE(m->decode(req, part).ok());
    float e[3], ed[3];
    m->eval(3, 2, 2, 1, e);
    ASSERT_TRUE(m->eval_dir(3, 2, d.lights.dirs[2], d.views.dirs[1], ed).ok());
    for (int c = 0; c < 3; ++c) {
      EXPECT_EQ(part.at(2, 1, 0, 0, size_t(c)), out.at(3, 2, 2, 1, size_t(c)));
      EXPECT_EQ(e[c], out.at(3, 2, 2, 1, size_t(c)));
      EXPECT_NEAR(ed[c], e[c], 1e-6);
    }
    std::remove(p.c_str());
  }
}

// ---- hostile files ----

TEST(Bonn, WrongSignatureIsRejected) {
  const std::string p = tmp_path("sig.btf");
  FileBuilder f;
  f.str("!DFMF07FCR and more bytes");
  f.save(p);
  EXPECT_FALSE(is_bonn_btf(p));
  auto r = read_bonn_info(p);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find(p), std::string::npos);
  EXPECT_NE(r.status().message().find("signature"), std::string::npos);
  EXPECT_FALSE(read_bonn_info(tmp_path("does_not_exist.btf")).ok());
  std::remove(p.c_str());
}

TEST(Bonn, EveryTruncatedPrefixFailsCleanly) {
  const BtfDesc d = small_desc(2, 2, 2, 2);
  std::vector<std::vector<uint8_t>> files;
  DfmfSpec s;
  s.ss = 2;
  files.push_back(build_dfmf(d, s));
  files.push_back(build_bdi(d, 2, 1, {1, 0, 1, 1}));
  files.push_back(build_bdi(d, 1, 1, {1, 1, 1, 1}));
  {
    FileBuilder f;  // FMF12FCER with a 1x1 height map
    f.common("!FMF12FCER", d);
    f.u8(2), f.u32(1), f.u32(1), f.u32(1), f.half(0);
    f.u32(1), f.u8(2), f.u32(1), f.u32(uint32_t(d.abrdf_size())), f.u32(4);
    for (size_t i = 0; i < 1 + d.abrdf_size() + 4; ++i) f.half(0.25f);
    files.push_back(f.b);
  }
  const std::string p = tmp_path("trunc.btf");
  for (const auto& full : files) {
    {
      FileBuilder f;
      f.b = full;
      f.save(p);
      ASSERT_TRUE(open_status(p).ok()) << open_status(p).message();
    }
    for (size_t n = 0; n < full.size(); ++n) {
      FileBuilder f;
      f.b.assign(full.begin(), full.begin() + std::ptrdiff_t(n));
      f.save(p);
      const Status st = open_status(p);
      ASSERT_FALSE(st.ok()) << "prefix " << n << " of " << full.size();
      ASSERT_NE(st.message().find(p), std::string::npos) << st.message();
    }
  }
  std::remove(p.c_str());
}

TEST(Bonn, StructSizeMismatchIsNamed) {
  const BtfDesc d = small_desc(2, 2, 2, 2);
  for (int delta : {-4, 4}) {
    FileBuilder f;
    f.str("!FMF06FC");
    f.meta(3, 3, delta);
    f.sampling(d);
    const std::string p = tmp_path("ss.btf");
    f.save(p);
    auto r = read_bonn_info(p);
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.status().message().find("struct_size"), std::string::npos) << r.status().message();
    std::remove(p.c_str());
  }
}

TEST(Bonn, HugeDimensionsAreRejectedBeforeAllocation) {
  const BtfDesc d = small_desc(1, 1, 1, 1);
  FileBuilder f;
  f.str("!DFMF08FCR");
  f.meta(1);
  f.sampling(d);
  f.u32(65000), f.u32(65000), f.u32(0);  // size, no rotations
  f.u32(100), f.i32(11);
  for (int i = 0; i < 12; ++i) f.f32(0);
  f.u8(2), f.u32(100), f.u32(1), f.u32(65000u * 65000u);  // a channel header claiming 4.2 G texels
  for (int i = 0; i < 20; ++i) f.u8(0);                   // ... and 20 bytes of data
  const std::string p = tmp_path("huge.btf");
  f.save(p);
  auto r = open_bonn_model(p);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::corrupt_data);
  EXPECT_NE(r.status().message().find("DFMF channel 0"), std::string::npos) << r.status().message();
  EXPECT_NE(r.status().message().find("exceeds the file"), std::string::npos) << r.status().message();
  // Overflowing products: num_rows x C x 8 wraps 64 bits only with huge values; u32 fields cannot,
  // but the multiplication is still checked. A mask of 65000 x 65000 BDI is rejected too.
  FileBuilder b;
  b.str("!BDIF06R2!");
  b.meta(4);
  b.sampling(d);
  b.u32(65000), b.u32(65000), b.u32(4), b.u8(0);
  for (int i = 0; i < 20; ++i) b.u8(1);
  b.save(p);
  auto rb = read_bonn_info(p);
  ASSERT_FALSE(rb.ok());
  EXPECT_NE(rb.status().message().find("BDI mask"), std::string::npos) << rb.status().message();
  std::remove(p.c_str());
}

TEST(Bonn, TrailingBytesAndInconsistentFieldsAreNamed) {
  const BtfDesc d = small_desc(2, 2, 2, 2);
  const std::string p = tmp_path("trail.btf");
  DfmfSpec s;
  FileBuilder f;
  f.b = build_dfmf(d, s);
  f.u8(0);
  f.save(p);
  auto r = read_bonn_info(p);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("1 trailing bytes"), std::string::npos) << r.status().message();
  // Light list that differs between views.
  FileBuilder g;
  g.str("!FMF06FC");
  g.meta(4);
  g.sampling(d, true);
  g.save(p);
  r = read_bonn_info(p);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("sampling view 1 light list"), std::string::npos) << r.status().message();
  // BDI chunk_bytes disagreeing with the layout.
  std::vector<uint8_t> bdi = build_bdi(d, 0, 2, {1, 1, 1, 1});
  const size_t chunk_hdr = bdi.size() - d.num_texels() * d.abrdf_size() * 2 - 4;
  bdi[chunk_hdr] ^= 2;
  FileBuilder h;
  h.b = bdi;
  h.save(p);
  r = read_bonn_info(p);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("BDI chunk 0 chunk_bytes"), std::string::npos) << r.status().message();
  // Corrupt bzip2 payload: open succeeds (structure is fine), decode names the chunk.
  std::vector<uint8_t> bz = build_bdi(d, 1, 2, {1, 1, 1, 1});
  bz[bz.size() - 8] ^= 0xff;
  h.b = bz;
  h.save(p);
  const Status st = open_status(p);
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.message().find("BDI chunk 0"), std::string::npos) << st.message();
  std::remove(p.c_str());
}

TEST(Bonn, WritersAreAtomicAndCheckTheHalfRange) {
  const Btf btf = synth(3, 3, 4, 2);
  auto model = encode_spec(btf, "fmf:rank=3:precision=float");
  EXPECT_FALSE(write_bonn_fmf(*model, "/nonexistent_dir/x.btf", true).ok());
  SynthOptions o;
  o.width = 3, o.height = 3, o.scale = 1e6f;
  o.lights = small_desc(3, 3, 4, 2).lights, o.views = small_desc(3, 3, 4, 2).views;
  auto hdr = encode_spec(synthesize_btf(o).value(), "fmf:rank=3:precision=float");
  const std::string p = tmp_path("hdr.btf");
  const Status s = write_bonn_fmf(*hdr, p, true);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("half range"), std::string::npos) << s.message();
  std::FILE* f = std::fopen(p.c_str(), "rb");
  EXPECT_EQ(f, nullptr);  // nothing left behind
  if (f) std::fclose(f);
  EXPECT_TRUE(write_bonn_fmf(*hdr, p, false).ok());
  std::remove(p.c_str());
}
