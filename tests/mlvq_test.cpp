// Tests of the mlvq codec: Huffman / bit-packing round trips, the 4D parameterisation and colour
// model, SSIM-threshold monotonicity, extremes (constant, all-zero, HDR 1e-6..1e6), storage and
// hostile files, and the OpenCL kernels against their C++ references.
#include <gtest/gtest.h>
#include <omp.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iterator>
#include <random>

#include "tests/require_cl.h"
#include "codecs/mlvq/mlvq.h"
#include "codecs/mlvq/mlvq_cl.h"
#include "codecs/mlvq/mlvq_internal.h"
#include "core/cl_runtime.h"
#include "core/metrics.h"
#include "core/synth.h"

using namespace btfc;
using namespace btfc::mlvq;

namespace {

Params params(const std::string& spec) {
  auto s = parse_spec_string(spec);
  EXPECT_TRUE(s.ok()) << s.status().message();
  auto p = bind_params(*s, mlvq_codec().params());
  EXPECT_TRUE(p.ok()) << p.status().message();
  return *p;
}

std::unique_ptr<Model> encode(const Btf& b, const std::string& spec) {
  Context ctx;
  auto m = mlvq_codec().encode(b, params(spec), ctx);
  EXPECT_TRUE(m.ok()) << m.status().message();
  return m.ok() ? std::move(m).value() : nullptr;
}

const Hierarchy& hier(const Model& m) { return dynamic_cast<const MlvqModel&>(m).hierarchy(); }

double stat(const Model& m, const std::string& key) {
  for (const auto& [k, v] : m.stats().numbers)
    if (k == key) return v;
  return NAN;
}
// Float32 bytes of the BTF / payload bytes: bench's ratio (mlvq's stats no longer repeat it).
double payload_ratio(const Model& m) { return double(m.desc().num_values()) * 4.0 / double(m.payload_bytes()); }

Btf synth(int w, int h, float scale = 1, uint64_t seed = 1) {
  SynthOptions o;
  o.width = w, o.height = h, o.scale = scale, o.seed = seed;
  auto r = synthesize_btf(o);
  EXPECT_TRUE(r.ok()) << r.status().message();
  return std::move(r).value();
}

Btf constant_btf(int w, int h, float r, float g, float b) {
  BtfDesc d;
  d.width = w, d.height = h, d.lights = DirectionSet::ubo2003(), d.views = DirectionSet::ubo2003();
  auto btf = Btf::create(d);
  EXPECT_TRUE(btf.ok());
  for (size_t i = 0; i < btf->size(); i += 3) btf->data()[i] = r, btf->data()[i + 1] = g, btf->data()[i + 2] = b;
  return std::move(btf).value();
}

Btf decode_all(const Model& m) {
  Btf out;
  EXPECT_TRUE(m.decode_all(out).ok());
  return out;
}


// A small textured BTF that encodes in well under a second.
const std::string k_small = "mlvq:phi=8:theta=4:alpha=7:beta=7";

}  // namespace

// ---- Huffman ---------------------------------------------------------------------------------

// At a measured (light, view): eval, eval_dir at its directions and eval_batch's `batch` (3
// floats) agree with the decode `d`.
static void expect_measured_agree(const Model& m, const Btf& d, const EvalQuery& q, const float* batch) {
  float e[3], ed[3];
  m.eval(q.x, q.y, q.light, q.view, e);
  ASSERT_TRUE(m.eval_dir(q.x, q.y, d.desc().lights.dirs[size_t(q.light)], d.desc().views.dirs[size_t(q.view)], ed).ok());
  for (int c = 0; c < 3; ++c) {
    const float want = d.at(size_t(q.x), size_t(q.y), size_t(q.light), size_t(q.view), size_t(c));
    EXPECT_NEAR(e[c], want, 1e-5f * (1 + std::fabs(want)));
    EXPECT_NEAR(ed[c], want, 1e-4f * (1 + std::fabs(want)));
    EXPECT_NEAR(batch[c], want, 1e-5f * (1 + std::fabs(want)));
  }
}

TEST(MlvqHuffman, RandomStreamsRoundTripAndNeverExceedPlainPlusFlag) {
  std::mt19937 rng(7);
  for (uint32_t alphabet : {1u, 2u, 3u, 17u, 256u, 1000u, 70000u}) {
    for (int skew = 0; skew < 3; ++skew) {
      const size_t n = 1 + rng() % 5000;
      std::vector<uint32_t> v(n);
      std::geometric_distribution<uint32_t> geo(skew == 2 ? 0.5 : 0.05);
      for (auto& x : v) x = skew == 0 ? uint32_t(rng() % alphabet) : std::min(alphabet - 1, geo(rng));
      const CodedStream cs = encode_indices(v, alphabet, true);
      const uint64_t plain = (uint64_t(n) * uint64_t(plain_bits(alphabet)) + 7) / 8;
      EXPECT_LE(cs.bytes.size(), plain + 1) << alphabet;
      EXPECT_EQ(cs.bytes.size(), std::min(cs.plain_bytes, cs.huffman_bytes));
      auto back = decode_indices(cs.bytes, n, alphabet, "test");
      ASSERT_TRUE(back.ok()) << back.status().message();
      EXPECT_EQ(back.value(), v) << "alphabet " << alphabet << " skew " << skew;
      const CodedStream off = encode_indices(v, alphabet, false);
      EXPECT_FALSE(off.huffman);
      EXPECT_EQ(decode_indices(off.bytes, n, alphabet, "test").value(), v);
    }
  }
  // A strongly skewed stream over a small alphabet is Huffman-coded and smaller.
  std::vector<uint32_t> sk(4000, 0);
  for (size_t i = 0; i < sk.size(); i += 50) sk[i] = uint32_t(1 + i % 15);
  const CodedStream cs = encode_indices(sk, 16, true);
  EXPECT_TRUE(cs.huffman);
  EXPECT_LT(cs.huffman_bytes, cs.plain_bytes / 2);
}

TEST(MlvqHuffman, RealIndexStreamsRoundTrip) {
  const Btf b = synth(8, 8);
  auto m = encode(b, k_small + ":scheme=2");
  ASSERT_TRUE(m);
  const Hierarchy& h = hier(*m);
  int streams = 0;
  auto check = [&](const std::vector<uint32_t>& v, uint32_t alphabet) {
    const CodedStream cs = encode_indices(v, alphabet, true);
    EXPECT_LE(cs.bytes.size(), (v.size() * size_t(plain_bits(alphabet)) + 7) / 8 + 1);
    auto back = decode_indices(cs.bytes, v.size(), alphabet, "real");
    ASSERT_TRUE(back.ok()) << back.status().message();
    EXPECT_EQ(back.value(), v);
    ++streams;
  };
  check(h.texel_idx, h.rgb[4].K);
  check(h.rgb[4].child, h.rgb[3].K);
  check(h.rgb[3].child, h.merge_size());
  check(h.lum[2].child, h.lum[1].K);
  check(h.chroma[2].child, h.chroma[1].K);
  check(h.merge_lum, h.lum[2].K);
  EXPECT_EQ(streams, 6);
  EXPECT_GE(stat(*m, "huffman_gain"), 1.0);
  EXPECT_LE(stat(*m, "payload_bytes"), stat(*m, "payload_bytes_plain"));
}

TEST(MlvqHuffman, CorruptStreamsGiveErrors) {
  std::vector<uint32_t> v(300, 1);
  v[0] = 0, v[100] = 2, v[200] = 3;
  const CodedStream cs = encode_indices(v, 4, true);
  ASSERT_TRUE(cs.huffman);
  for (size_t n = 0; n < cs.bytes.size(); ++n) {
    auto r = decode_indices(std::span<const uint8_t>(cs.bytes.data(), n), v.size(), 4, "stream 'x'");
    EXPECT_FALSE(r.ok()) << n;
  }
  std::vector<uint8_t> b = cs.bytes;
  b[0] = 7;
  EXPECT_FALSE(decode_indices(b, v.size(), 4, "x").ok());
  const CodedStream plain = encode_indices(v, 4, false);
  std::vector<uint8_t> p = plain.bytes;
  EXPECT_FALSE(decode_indices(p, v.size(), 3, "x").ok());  // index 3 is out of range for 3 entries
}

// ---- parameterisation and colour -------------------------------------------------------------

TEST(MlvqGrid, NodesMapBackToTheirCoordinatesAndColourRoundTrips) {
  Grid g;
  for (int ip = 0; ip < g.nphi; ip += 3)
    for (int it = 1; it < g.ntheta; ++it)
      for (int ia = 0; ia < g.nalpha; ia += 2)
        for (int ib = 1; ib + 1 < g.nbeta; ib += 2) {
          Vec3 wl, wv;
          node_dirs(g, ip, it, ia, ib, wl, wv);
          const GridCoord c = grid_coord(g, wl, wv);
          EXPECT_NEAR(c.phi, ip, 2e-3);
          EXPECT_NEAR(c.theta, it, 2e-3);
          EXPECT_NEAR(c.alpha, ia, 2e-3);
          EXPECT_NEAR(c.beta, ib, 2e-3);
        }
  // The mirror direction lands at alpha = -theta_v, beta = 0 for any view azimuth.
  for (double pv : {0.3, 2.0, 4.5}) {
    const Vec3 wv = dir_from_theta_phi(0.5, pv), wl = dir_from_theta_phi(0.5, pv + 3.14159265358979);
    const GridCoord c = grid_coord(g, wl, wv);
    EXPECT_NEAR(c.alpha, (-0.5 / 3.14159265358979 * 180 + 90) / 18.0, 1e-3);
    EXPECT_NEAR(c.beta, 5.0, 1e-3);
  }
  const float rgb[3] = {0.2f, 0.5f, 0.1f};
  float lrg[3], back[3];
  rgb_to_lrg(rgb, lrg);
  lrg_to_rgb(lrg, back);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(back[c], rgb[c], 1e-6);
}

// ---- extremes --------------------------------------------------------------------------------

TEST(MlvqExtremes, ConstantBtfHasOneEntryPerLevelInEveryScheme) {
  const Btf b = constant_btf(6, 5, 0.3f, 0.2f, 0.1f);
  for (int s = 1; s <= 4; ++s) {
    auto m = encode(b, "mlvq:scheme=" + std::to_string(s));
    ASSERT_TRUE(m);
    const Hierarchy& h = hier(*m);
    for (int k = 1; k <= 4; ++k) {
      if (k > s) {
        EXPECT_EQ(h.rgb[k].K, 1u) << s << " " << k;
      } else {
        EXPECT_EQ(h.lum[k].K, 1u) << s << " " << k;
        EXPECT_EQ(h.chroma[k].K, 1u) << s << " " << k;
      }
    }
    EXPECT_EQ(h.merge_size(), 1u);
    const Btf d = decode_all(*m);
    double mx = 0;
    for (size_t i = 0; i < d.size(); ++i) mx = std::max(mx, double(std::fabs(d.data()[i] - b.data()[i])));
    // Half-float chromaticity (2^-11 relative) and the 3.7 % 8-bit scale steps bound the error.
    EXPECT_LE(mx, 0.3 * 0.02) << s;
  }
}

TEST(MlvqExtremes, AllZeroDataDecodesToZero) {
  const Btf b = constant_btf(4, 3, 0, 0, 0);
  auto m = encode(b, k_small + ":scheme=best");
  ASSERT_TRUE(m);
  const Hierarchy& h = hier(*m);
  for (float s : h.texel_scale) EXPECT_EQ(s, 0.f);
  const Btf d = decode_all(*m);
  for (size_t i = 0; i < d.size(); ++i) ASSERT_EQ(d.data()[i], 0.f);
  float v[3];
  ASSERT_TRUE(m->eval_dir(1, 1, dir_from_theta_phi(0.3, 1), dir_from_theta_phi(0.2, 2), v).ok());
  EXPECT_EQ(v[0], 0.f);
}

TEST(MlvqExtremes, HdrFromOneMillionthToOneMillionUses16BitScales) {
  Btf b = synth(6, 6);
  const size_t n = b.desc().num_texels(), a = b.desc().abrdf_size();
  for (size_t t = 0; t < n; ++t) {
    const float f = float(std::pow(10.0, -6.0 + 12.0 * double(t) / double(n - 1)));
    for (size_t r = 0; r < a; ++r) b.abrdf(t)[r] *= f;
  }
  // noise=off: the image-domain noise estimate reads these 100x jumps between neighbours as noise
  // (mlvq.h); this test is about the scales' range, at fixed thresholds.
  auto m = encode(b, k_small + ":scheme=2:noise=off");
  ASSERT_TRUE(m);
  EXPECT_EQ(hier(*m).scale_bits, 16);  // the texels' peaks span 1e12: auto picks the unclipped 16-bit codes
  const Btf d = decode_all(*m);
  // Per-texel relative L2 error: every texel keeps its magnitude (within the VQ error), from
  // 1e-6 to 1e6 alike.
  double worst = 0;
  for (size_t t = 0; t < n; ++t) {
    double num = 0, den = 0;
    for (size_t r = 0; r < a; ++r) {
      const double e = double(d.abrdf(t)[r]) - b.abrdf(t)[r];
      num += e * e, den += double(b.abrdf(t)[r]) * b.abrdf(t)[r];
    }
    worst = std::max(worst, std::sqrt(num / den));
  }
  EXPECT_LE(worst, 0.6);
  EXPECT_GE(worst, 0.05);
}

// ---- quality and thresholds ------------------------------------------------------------------

TEST(MlvqQuality, StricterThresholdsNeverGiveSmallerFilesOrLowerSsim) {
  const Btf b = synth(8, 8, 1, 3);
  double prev_bytes = 0, prev_ssim = 0;
  for (double t : {0.5, 0.8, 0.9, 0.97, 0.995}) {
    const std::string ts = std::to_string(t);
    auto m = encode(b, k_small + ":scheme=2:ssim4=" + ts + ":ssim3=" + ts + ":ssim2=" + ts + ":ssim1=" + ts);
    ASSERT_TRUE(m);
    auto mt = compare_btf(b, decode_all(*m));
    ASSERT_TRUE(mt.ok());
    const double bytes = double(m->payload_bytes());
    EXPECT_GE(bytes, prev_bytes) << t;
    EXPECT_GE(mt->mean_ssim, prev_ssim - 1e-9) << t;
    prev_bytes = bytes, prev_ssim = mt->mean_ssim;
  }
}

TEST(MlvqQuality, DefaultEncodingErrorAndEvalConsistency) {
  const Btf b = synth(8, 8);
  auto m = encode(b, "mlvq:scheme=2");
  ASSERT_TRUE(m);
  auto mt = compare_btf(b, decode_all(*m));
  ASSERT_TRUE(mt.ok());
  EXPECT_LE(mt->rel_l2, 0.3);
  EXPECT_GE(mt->rel_l2, 0.02);
  const double rs = stat(*m, "resample_rel_rmse");
  EXPECT_GT(rs, 0.0);
  EXPECT_LE(rs, mt->rel_l2 * 1.5);
  // eval, eval_dir at the measured directions, eval_batch and decode agree.
  const Btf d = decode_all(*m);
  std::vector<EvalQuery> q;
  for (int i = 0; i < 50; ++i) q.push_back({i % 8, (i / 8) % 8, (i * 7) % 81, (i * 13) % 81, {}, {}});
  std::vector<float> out(3 * q.size());
  ASSERT_TRUE(m->eval_batch(q, out.data()).ok());
  for (size_t i = 0; i < q.size(); ++i) expect_measured_agree(*m, d, q[i], &out[3 * i]);
}

TEST(MlvqQuality, BestSchemeIsTheSmallestOfTheFour) {
  const Btf b = synth(8, 8, 1, 5);
  auto m = encode(b, k_small);
  ASSERT_TRUE(m);
  const int s = int(stat(*m, "scheme"));
  const double chosen = stat(*m, "payload_bytes");
  EXPECT_EQ(chosen, stat(*m, "scheme" + std::to_string(s) + ".payload_bytes"));
  for (int k = 1; k <= 4; ++k) {
    if (stat(*m, "scheme" + std::to_string(k) + ".mean_texel_ssim") >= stat(*m, "mean_texel_ssim") - 0.005) {
      EXPECT_LE(chosen, stat(*m, "scheme" + std::to_string(k) + ".payload_bytes")) << k;
    }
  }
}

// ---- storage ---------------------------------------------------------------------------------

TEST(MlvqStorage, SaveLoadDecodesIdenticallyAndHostileFilesFailCleanly) {
  ocl::set_device_choice(ocl::DeviceChoice::cpu);
  const Btf b = synth(5, 4);
  auto m = encode(b, k_small + ":scheme=3");
  ASSERT_TRUE(m);
  const std::string path = ::testing::TempDir() + "mlvq_" + std::to_string(::getpid()) + ".btfc";
  ASSERT_TRUE(save_model(*m, mlvq_codec(), path).ok());
  {
    auto rd = ContainerReader::open(path);
    ASSERT_TRUE(rd.ok()) << rd.status().message();
    auto lm = load_model(rd.value());
    ASSERT_TRUE(lm.ok()) << lm.status().message();
    const Btf a = decode_all(*m), c = decode_all(*lm.value());
    ASSERT_EQ(a.size(), c.size());
    for (size_t i = 0; i < a.size(); ++i) ASSERT_EQ(a.data()[i], c.data()[i]);
    EXPECT_EQ(lm.value()->payload_bytes(), m->payload_bytes());
  }
  // Every truncated prefix fails with an error naming the file.
  std::ifstream in(path, std::ios::binary);
  const std::vector<char> bytes{std::istreambuf_iterator<char>(in), {}};
  const std::string tp = path + ".trunc";
  for (size_t n = 0; n < bytes.size(); n += std::max<size_t>(1, bytes.size() / 97)) {
    std::ofstream(tp, std::ios::binary).write(bytes.data(), std::streamsize(n));
    auto rd = ContainerReader::open(tp);
    if (!rd.ok()) {
      EXPECT_NE(rd.status().message().find(tp), std::string::npos);
      continue;
    }
    auto lm = load_model(rd.value());
    EXPECT_FALSE(lm.ok()) << n;
  }
  // Valid container, hostile content: an index stream pointing past its codebook, a wrong
  // scheme, a bad scale range.
  auto rewrite = [&](const std::string& victim, auto mutate) {
    auto rd = ContainerReader::open(path);
    ContainerWriter w;
    w.set_desc(rd->desc());
    w.set_codec(rd->codec());
    for (const TensorInfo& ti : rd->tensors()) {
      Tensor t = rd->read(ti.name).value();
      if (ti.name == victim) mutate(t);
      w.add_tensor(std::move(t));
    }
    ASSERT_TRUE(w.write(tp).ok());
    auto r2 = ContainerReader::open(tp);
    ASSERT_TRUE(r2.ok());
    auto lm = load_model(r2.value());
    EXPECT_FALSE(lm.ok()) << victim;
    if (!lm.ok()) {
      EXPECT_NE(lm.status().message().find(tp), std::string::npos) << lm.status().message();
    }
  };
  rewrite("texel.idx", [](Tensor& t) {
    t.bytes.pop_back();
    t.shape = {uint64_t(t.bytes.size())};
  });
  rewrite("rgb4.idx", [](Tensor& t) {
    t.bytes.assign(t.bytes.size(), 0xff);
    t.bytes[0] = 1;  // a Huffman table of 31-bit code lengths
  });
  rewrite("mlvq", [](Tensor& t) { t.bytes[0] = 9; });
  rewrite("texel.range", [](Tensor& t) {
    const float nan = NAN;
    std::memcpy(t.bytes.data(), &nan, 4);
  });
  rewrite("books", [](Tensor& t) { t.bytes[4 * 4] ^= 0x40; });
  std::remove(path.c_str());
  std::remove(tp.c_str());
  ocl::set_device_choice(ocl::DeviceChoice::automatic);
}

TEST(MlvqStorage, ParametersAreValidated) {
  auto s = parse_spec_string("mlvq:beta=10");
  auto p = bind_params(*s, mlvq_codec().params());
  ASSERT_TRUE(p.ok());
  Context ctx;
  auto r = mlvq_codec().encode(synth(2, 2), p.value(), ctx);
  EXPECT_FALSE(r.ok());
  EXPECT_FALSE(bind_params(*parse_spec_string("mlvq:ssim1=1.5"), mlvq_codec().params()).ok());
  EXPECT_FALSE(bind_params(*parse_spec_string("mlvq:scheme=5"), mlvq_codec().params()).ok());
  EXPECT_FALSE(bind_params(*parse_spec_string("mlvq:bogus=1"), mlvq_codec().params()).ok());
}

TEST(MlvqStorage, GpuTensorsDescribeTheHierarchy) {
  auto m = encode(synth(4, 4), k_small + ":scheme=1");
  ASSERT_TRUE(m);
  auto ts = m->gpu_tensors();
  ASSERT_TRUE(ts.ok());
  const Hierarchy& h = hier(*m);
  bool idx = false, l1 = false, rgb2 = false;
  for (const Tensor& t : ts.value()) {
    if (t.name == "texel_index") idx = t.shape == std::vector<uint64_t>{4, 4};
    if (t.name == "lum1") l1 = t.shape == std::vector<uint64_t>{h.lum[1].K, 7};
    if (t.name == "rgb2_index") rgb2 = t.shape == std::vector<uint64_t>{h.rgb[2].K, 7};
  }
  EXPECT_TRUE(idx && l1 && rgb2);
}

// ---- the codebook search's SSIM scan -----------------------------------------------------------

// ssim_margins (the vectorized scan, this CPU's clone) against the one-pair formula, bit for bit,
// for real vectors' moments and the corner cases: a zero entry (see = 0), a zero candidate (peak
// 0: the formula's early 1), anti-correlated vectors (a negative dot: scale 0), each part alone
// and both, over runs that are not a multiple of any vector width and start mid-codebook.
TEST(MlvqSearch, ScanGivesTheFormulasBitsForEveryPair) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> u(0, 1);
  const int nl = 9, nc = 18;
  auto moments = [&](std::vector<float>& v, int kind) {  // kind 0: random, 1: zero, 2: negative
    for (float& x : v) x = kind == 1 ? 0.f : kind == 2 ? -u(rng) : u(rng) * u(rng) * 4;
  };
  const size_t K = 203;
  std::vector<std::vector<float>> el(K, std::vector<float>(nl)), ec(K, std::vector<float>(nc));
  for (size_t j = 0; j < K; ++j) moments(el[j], j % 17 == 3 ? 1 : 0), moments(ec[j], j % 13 == 5 ? 1 : 0);
  auto sums = [](const std::vector<float>& a, const std::vector<float>& b) {
    double s = 0;
    for (size_t i = 0; i < a.size(); ++i) s += double(a[i]) * b[i];
    return s;
  };
  auto sum = [](const std::vector<float>& a) {
    double s = 0;
    for (float x : a) s += x;
    return s;
  };
  for (int part = 0; part < 3; ++part) {  // 0: luminance only, 1: chromaticity only, 2: both
    const double n_lum = part != 1 ? nl : 0, n_chroma = part != 0 ? nc : 0;
    EntryTerms terms;
    for (size_t j = 0; j < K; ++j) terms.add(n_lum, n_chroma, sum(el[j]), sums(el[j], el[j]), sum(ec[j]), sums(ec[j], ec[j]));
    for (int c = 0; c < 12; ++c) {
      std::vector<float> xl(nl), xc(nc);
      moments(xl, c % 4 == 1 ? 1 : c % 4 == 2 ? 2 : 0), moments(xc, c % 3 == 1 ? 1 : 0);
      ScanCandidate x;
      x.n_lum = n_lum, x.sx = sum(xl), x.sxx = sums(xl, xl), x.L = 0;
      for (float v : xl) x.L = std::max(x.L, double(v));
      x.n_chroma = n_chroma, x.sxc = sum(xc), x.sxxc = sums(xc, xc);
      x.thr_l = 0.9, x.thr_c = 0.7;
      const size_t j0 = size_t(c) * 7 % 40, k = K - j0;
      std::vector<float> gl(k), gc(k);
      for (size_t j = 0; j < k; ++j) gl[j] = float(sums(xl, el[j0 + j])), gc[j] = float(sums(xc, ec[j0 + j]));
      std::vector<double> margin(k), scale(k);
      ssim_margins(x, terms, j0, k, gl.data(), gc.data(), margin.data(), scale.data());
      int scaled_zero = 0;
      for (size_t j = 0; j < k; ++j) {
        const size_t e = j0 + j;
        double want = 2, sc = 1;
        if (n_lum > 0) want = ssim_from_moments(n_lum, x.sx, x.sxx, sum(el[e]), sums(el[e], el[e]), gl[j], x.L, true, &sc) - x.thr_l;
        if (n_chroma > 0)
          want = std::min(want, ssim_from_moments(n_chroma, x.sxc, x.sxxc, sum(ec[e]), sums(ec[e], ec[e]), gc[j], 1.0, false, nullptr) - x.thr_c);
        ASSERT_EQ(std::memcmp(&margin[j], &want, sizeof want), 0) << "part " << part << " candidate " << c << " entry " << e << ": " << margin[j] << " vs " << want;
        ASSERT_EQ(std::memcmp(&scale[j], &sc, sizeof sc), 0) << "part " << part << " candidate " << c << " entry " << e;
        scaled_zero += n_lum > 0 && sc == 0;
      }
      if (n_lum > 0 && c % 4 == 2) {
        EXPECT_GT(scaled_zero, 0);  // the negative candidate's scales clamp at 0
      }
    }
  }
}

// The search scans the codebook in blocks of candidates and chunks of 1024 entries (codebook.cpp,
// search_entries): the model may not depend on how many threads ran the blocks, and a noisy BTF
// grows codebooks past one chunk.
TEST(MlvqSearch, ModelDoesNotDependOnTheThreadCount) {
  SynthOptions o;
  o.width = 12, o.height = 12, o.seed = 5, o.noise = 0.1f, o.scale = 300;
  auto b = synthesize_btf(o);
  ASSERT_TRUE(b.ok()) << b.status().message();
  const int threads = omp_get_max_threads();
  std::vector<float> first;
  double most = 0;
  for (int t : {1, 2, 3}) {
    omp_set_num_threads(t);
    auto m = encode(*b, "mlvq");
    omp_set_num_threads(threads);
    ASSERT_TRUE(m);
    for (const char* part : {"lum", "chroma"})
      for (int k = 1; k <= 4; ++k) most = std::max(most, stat(*m, std::string("entries.") + part + std::to_string(k)));
    const Btf out = decode_all(*m);
    const std::vector<float> v(out.data(), out.data() + out.size());
    if (first.empty()) first = v;
    else EXPECT_TRUE(v == first) << t << " threads";
  }
  EXPECT_GT(most, 1024);  // two chunks of entries or more
}

// ---- OpenCL kernels vs C++ references --------------------------------------------------------

TEST(MlvqOpenCL, SsimSearchKernelMatchesReference) {
  REQUIRE_CL();
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(0, 1);
  for (auto [dl, dc] : {std::pair{11, 22}, {121, 0}, {0, 26}}) {
    const int B = 37, K = 53;
    std::vector<float> Xl(size_t(B * dl)), Xc(size_t(B * dc)), El(size_t(K * dl)), Ec(size_t(K * dc));
    for (auto* v : {&Xl, &Xc, &El, &Ec})
      for (float& x : *v) x = u(rng);
    // A few candidates are scaled copies of entries, so the best match is known.
    for (int i = 0; i < 5 && dl; ++i)
      for (int j = 0; j < dl; ++j) Xl[size_t(i * dl + j)] = 2.5f * El[size_t((7 * i) * dl + j)];
    std::vector<double> xm(size_t(5 * B), 0), em(size_t(4 * K), 0);
    for (int i = 0; i < B; ++i) {
      for (int j = 0; j < dl; ++j) xm[size_t(5 * i)] += Xl[size_t(i * dl + j)], xm[size_t(5 * i + 1)] += double(Xl[size_t(i * dl + j)]) * Xl[size_t(i * dl + j)], xm[size_t(5 * i + 2)] = std::max(xm[size_t(5 * i + 2)], double(Xl[size_t(i * dl + j)]));
      for (int j = 0; j < dc; ++j) xm[size_t(5 * i + 3)] += Xc[size_t(i * dc + j)], xm[size_t(5 * i + 4)] += double(Xc[size_t(i * dc + j)]) * Xc[size_t(i * dc + j)];
    }
    for (int i = 0; i < K; ++i) {
      for (int j = 0; j < dl; ++j) em[size_t(4 * i)] += El[size_t(i * dl + j)], em[size_t(4 * i + 1)] += double(El[size_t(i * dl + j)]) * El[size_t(i * dl + j)];
      for (int j = 0; j < dc; ++j) em[size_t(4 * i + 2)] += Ec[size_t(i * dc + j)], em[size_t(4 * i + 3)] += double(Ec[size_t(i * dc + j)]) * Ec[size_t(i * dc + j)];
    }
    // Different luminance / chromaticity thresholds: the scores are margins over them.
    SearchProblem p{B, K, dl, dc, Xl.data(), Xc.data(), El.data(), Ec.data(), xm.data(), em.data(), 0.9f, 0.8f};
    SearchResult ref, cl;
    ssim_search_reference(p, ref);
    ASSERT_TRUE(ssim_search_cl(p, cl).ok());
    for (int i = 0; i < B; ++i) {
      EXPECT_NEAR(cl.sim[size_t(i)], ref.sim[size_t(i)], 1e-5);
      if (std::fabs(cl.sim[size_t(i)] - ref.sim[size_t(i)]) < 1e-6) {
        EXPECT_EQ(cl.idx[size_t(i)], ref.idx[size_t(i)]);
      }
      EXPECT_NEAR(cl.scale[size_t(i)], ref.scale[size_t(i)], 1e-4 * (1 + ref.scale[size_t(i)]));
    }
    if (dl && !dc) {
      for (int i = 0; i < 5; ++i) {
        EXPECT_EQ(ref.idx[size_t(i)], 7 * i);
        EXPECT_NEAR(ref.scale[size_t(i)], 2.5f, 1e-4);
        EXPECT_NEAR(ref.sim[size_t(i)], 1.f - 0.9f, 1e-5);
      }
    }
  }
}

TEST(MlvqOpenCL, ColourConversionKernelMatchesReference) {
  REQUIRE_CL();
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(-0.1f, 2);
  std::vector<float> rgb(3 * 1001);
  for (float& x : rgb) x = u(rng);
  rgb[0] = rgb[1] = rgb[2] = 0;
  std::vector<float> a(rgb.size()), b(rgb.size());
  rgb_to_lrg_reference(rgb, a.data());
  ASSERT_TRUE(rgb_to_lrg_cl(rgb, b.data()).ok());
  for (size_t i = 0; i < a.size(); ++i) EXPECT_NEAR(a[i], b[i], 1e-6f * (1 + std::fabs(a[i])));
}

TEST(MlvqOpenCL, BatchedDecodeKernelMatchesReferenceAndModel) {
  REQUIRE_CL();
  for (int s = 1; s <= 4; ++s) {
    auto m = encode(synth(6, 5, 1, uint64_t(s)), k_small + ":scheme=" + std::to_string(s));
    ASSERT_TRUE(m);
    const Hierarchy& h = hier(*m);
    const FlatModel f = flatten(h);
    std::mt19937 rng{uint32_t(s)};
    std::uniform_real_distribution<float> u(0, 1);
    const size_t n = 3000;
    std::vector<int> texel(n);
    std::vector<float> coord(4 * n);
    for (size_t i = 0; i < n; ++i) {
      texel[i] = int(rng() % 30);
      coord[4 * i] = u(rng) * float(h.grid.nphi), coord[4 * i + 1] = u(rng) * float(h.grid.ntheta - 1);
      coord[4 * i + 2] = u(rng) * float(h.grid.nalpha - 1), coord[4 * i + 3] = u(rng) * float(h.grid.nbeta - 1);
    }
    std::vector<float> ref(3 * n), cl(3 * n);
    eval_flat_reference(f, texel, coord, ref.data());
    auto dev = DeviceModel::upload(f);
    ASSERT_TRUE(dev.ok()) << dev.status().message();
    ASSERT_TRUE(dev.value()->eval(texel, coord, cl.data()).ok());
    for (size_t i = 0; i < n; ++i) {
      float mv[3];
      eval_stencil(h, size_t(texel[i]), stencil(h.grid, GridCoord{coord[4 * i], coord[4 * i + 1], coord[4 * i + 2], coord[4 * i + 3]}), mv);
      for (int c = 0; c < 3; ++c) {
        const float tol = 1e-5f * (1 + std::fabs(ref[3 * i + size_t(c)]));
        EXPECT_NEAR(cl[3 * i + size_t(c)], ref[3 * i + size_t(c)], tol);
        EXPECT_NEAR(mv[c], ref[3 * i + size_t(c)], tol);
      }
    }
  }
}

// ---- the measured layout (payload version 2) -----------------------------------------------------

// Measured: rel_l2 0.2964 for the default on synth(6, 6, 1, 7) (0.374 before the noise estimate
// took the texture that repeats in the partner image for texture: noise.cpp).
constexpr double SYN_REL = 0.32;

TEST(MlvqMeasured, LayoutCoversTheMeasuredPairsOnce) {
  BtfDesc d;
  d.width = d.height = 1, d.channels = 3, d.lights = DirectionSet::ubo2003(), d.views = DirectionSet::ubo2003();
  const Grid g = measured_grid(d);
  EXPECT_TRUE(g.measured());
  EXPECT_EQ(g.nphi, 9);
  EXPECT_EQ(g.ntheta, 9);
  EXPECT_EQ(g.nalpha, 9);
  EXPECT_EQ(g.nbeta, 9);
  std::vector<int> seen(81 * 81, 0);
  for (size_t node = 0; node < g.size(); ++node) {
    uint32_t l, v;
    node_measured(g, node, l, v);
    seen[l + 81 * v]++;
    const Stencil s = measured_stencil(g, d, l, v);
    EXPECT_EQ(size_t(s.i[0][0]) + 9 * (size_t(s.i[1][0]) + 9 * (size_t(s.i[2][0]) + 9 * size_t(s.i[3][0]))), node);
  }
  for (int c : seen) EXPECT_EQ(c, 1);
  // Sets that do not factor: groups overhang and the padding repeats the last direction.
  d.lights.dirs.resize(13), d.views.dirs.resize(7);
  const Grid h = measured_grid(d);
  EXPECT_EQ(h.nbeta, 4);
  EXPECT_EQ(h.nalpha, 4);
  EXPECT_EQ(h.ntheta, 3);
  EXPECT_EQ(h.nphi, 3);
  uint32_t l, v;
  node_measured(h, h.size() - 1, l, v);
  EXPECT_EQ(l, 12u);
  EXPECT_EQ(v, 6u);
}

TEST(MlvqMeasured, NoResamplingErrorAndEvalPathsAgree) {
  const Btf b = synth(6, 6, 1, 7);
  auto m = encode(b, "mlvq");
  ASSERT_TRUE(m);
  EXPECT_TRUE(hier(*m).grid.measured());
  EXPECT_EQ(stat(*m, "layout_measured"), 1);
  EXPECT_LE(stat(*m, "resample_rel_rmse"), 1e-6);
  auto mt = compare_btf(b, decode_all(*m));
  ASSERT_TRUE(mt.ok());
  std::printf("measured default: rel_l2 %.4f mssim %.4f ratio %.1f\n", mt->rel_l2, mt->mean_ssim, payload_ratio(*m));
  // Measured: rel_l2 see the bounds (two-sided, 0.75 x bound <= value <= bound).
  EXPECT_LE(mt->rel_l2, SYN_REL);
  EXPECT_GE(mt->rel_l2, 0.75 * SYN_REL);
  const Btf d = decode_all(*m);
  std::vector<EvalQuery> q;
  for (int i = 0; i < 60; ++i) q.push_back({i % 6, (i / 6) % 6, (i * 7) % 81, (i * 13) % 81, {}, {}});
  // Arbitrary directions: eval_batch blends the 3 x 3 measured pairs as eval_dir does, bit for bit.
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> th(0, 1.3), ph(0, 6.28);
  for (int i = 0; i < 40; ++i) q.push_back({i % 6, (i / 5) % 6, -1, -1, dir_from_theta_phi(th(rng), ph(rng)), dir_from_theta_phi(th(rng), ph(rng))});
  std::vector<float> out(3 * q.size());
  ASSERT_TRUE(m->eval_batch(q, out.data()).ok());
  for (size_t i = 0; i < q.size(); ++i) {
    float ed[3];
    if (q[i].light >= 0) {
      expect_measured_agree(*m, d, q[i], &out[3 * i]);
    } else {
      ASSERT_TRUE(m->eval_dir(q[i].x, q[i].y, q[i].wl, q[i].wv, ed).ok());
      for (int c = 0; c < 3; ++c) EXPECT_EQ(out[3 * i + size_t(c)], ed[c]);  // the same sums, the same order
    }
  }
}

TEST(MlvqMeasured, SaveLoadIsExactWithQuantizedValuesAndScales) {
  const Btf b = synth(5, 4, 30, 2);  // HDR: 10-bit scales
  auto m = encode(b, "mlvq");
  ASSERT_TRUE(m);
  EXPECT_EQ(hier(*m).scale_bits, 10);
  EXPECT_EQ(hier(*m).value_bits, 8);
  const std::string path = ::testing::TempDir() + "mlvq_meas_" + std::to_string(::getpid()) + ".btfc";
  ASSERT_TRUE(save_model(*m, mlvq_codec(), path).ok());
  auto rd = ContainerReader::open(path);
  ASSERT_TRUE(rd.ok()) << rd.status().message();
  EXPECT_EQ(rd->codec().payload_version, 2u);
  EXPECT_EQ(rd->find("lum1.values")->dtype, DType::zq);
  auto lm = load_model(rd.value());
  ASSERT_TRUE(lm.ok()) << lm.status().message();
  EXPECT_TRUE(hier(*lm.value()).grid.measured());
  EXPECT_EQ(hier(*lm.value()).value_bits, 8);
  const Btf a = decode_all(*m), c = decode_all(*lm.value());
  ASSERT_EQ(a.size(), c.size());
  for (size_t i = 0; i < a.size(); ++i) ASSERT_EQ(a.data()[i], c.data()[i]);
  EXPECT_EQ(lm.value()->payload_bytes(), m->payload_bytes());
  // A layout word the reader does not know, and a measured layout that does not fit the BTF.
  for (int what = 0; what < 2; ++what) {
    ContainerWriter w;
    w.set_desc(rd->desc());
    w.set_codec(rd->codec());
    for (const TensorInfo& ti : rd->tensors()) {
      Tensor t = rd->read(ti.name).value();
      if (ti.name == "mlvq") {
        if (what == 0) t.bytes[28] = 7;
        else t.bytes[4] = 5;  // nphi
      }
      w.add_tensor(std::move(t));
    }
    const std::string tp = path + ".bad";
    ASSERT_TRUE(w.write(tp).ok());
    auto r2 = ContainerReader::open(tp);
    ASSERT_TRUE(r2.ok());
    auto bad = load_model(r2.value());
    EXPECT_FALSE(bad.ok()) << what;
    if (!bad.ok()) {
      EXPECT_NE(bad.status().message().find("layout"), std::string::npos) << bad.status().message();
    }
    std::remove(tp.c_str());
  }
  std::remove(path.c_str());
}

TEST(MlvqMeasured, RatioFloorRelaxesTheThresholds) {
  const Btf b = synth(6, 6, 1, 4);
  auto strict = encode(b, "mlvq:min_ratio=0:ssim4=0.99:ssim3=0.99:ssim2=0.99:ssim1=0.99:noise=off");
  auto floored = encode(b, "mlvq:min_ratio=1e6:ssim4=0.99:ssim3=0.99:ssim2=0.99:ssim1=0.99:noise=off");
  ASSERT_TRUE(strict && floored);
  EXPECT_EQ(stat(*strict, "relaxed"), 0);
  EXPECT_EQ(stat(*floored, "relaxed"), 4);  // 1e6 : 1 is out of reach: four relaxations, then stop
  EXPECT_NEAR(stat(*floored, "threshold.lum1"), 1 - 0.01 * std::pow(1.6, 4), 1e-9);
  EXPECT_LT(floored->payload_bytes(), strict->payload_bytes());
}
