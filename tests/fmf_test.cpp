// Tests of the fmf codec: SVD optimality (Eckart-Young), randomized accuracy, storage, extremes.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <cstdio>
#include <random>

#include "codecs/codec.h"
#include "codecs/fmf/fmf.h"
#include "core/svd.h"
#include "core/interp.h"
#include "core/metrics.h"
#include "tests/codec_test_util.h"

using namespace btfc;

namespace {

using test::encode_spec;

BtfDesc make_desc(int w, int h, int nl, int nv) {
  BtfDesc d;
  d.width = w, d.height = h;
  for (int i = 0; i < nl; ++i) d.lights.dirs.push_back(dir_from_theta_phi(0.12 * (i % 7), 0.9 * i));
  for (int i = 0; i < nv; ++i) d.views.dirs.push_back(dir_from_theta_phi(0.15 * (i % 5), 1.3 * i));
  d.lights.name = d.views.name = "custom";
  return d;
}

// B = sum_k decay^k u_k v_k^T + noise (+ offset), filled through the matrix view.
Btf random_btf(const BtfDesc& d, int rank, double decay, double noise, double offset, unsigned seed) {
  Btf b = Btf::create(d).value();
  std::mt19937 rng(seed);
  std::normal_distribution<double> g(0, 1);
  const size_t m = d.abrdf_size(), n = d.num_texels();
  Eigen::MatrixXd U(m, rank), V(n, rank);
  for (int i = 0; i < U.size(); ++i) U.data()[i] = g(rng);
  for (int i = 0; i < V.size(); ++i) V.data()[i] = g(rng);
  Eigen::MatrixXd B = Eigen::MatrixXd::Constant(m, n, offset);
  for (int k = 0; k < rank; ++k) B += std::pow(decay, k) * U.col(k) * V.col(k).transpose() / std::sqrt(double(m));
  for (size_t j = 0; j < n; ++j)
    for (size_t i = 0; i < m; ++i) b.data()[j * m + i] = float(B(i, j) + noise * g(rng));
  return b;
}

Eigen::MatrixXd as_matrix(const Btf& b) {
  return Eigen::Map<const Eigen::MatrixXf>(b.data(), Eigen::Index(b.desc().abrdf_size()), Eigen::Index(b.desc().num_texels())).cast<double>();
}

double sq_error(const Btf& a, const Btf& b) {
  double e = 0;
  for (size_t i = 0; i < a.size(); ++i) e += (double(a.data()[i]) - b.data()[i]) * (double(a.data()[i]) - b.data()[i]);
  return e;
}

double stat(const Model& m, const std::string& key) {
  for (const auto& [k, v] : m.stats().numbers)
    if (k == key) return v;
  return NAN;
}
std::string note(const Model& m, const std::string& key) {
  for (const auto& [k, v] : m.stats().notes)
    if (k == key) return v;
  return "";
}

// Independent reference: singular values from Eigen's Jacobi SVD in double.
Eigen::VectorXd singular_values(const Btf& b) { return Eigen::JacobiSVD<Eigen::MatrixXd>(as_matrix(b)).singularValues(); }

std::string tmp_path(const std::string& name) { return ::testing::TempDir() + "fmf_test_" + std::to_string(::getpid()) + "_" + name; }

}  // namespace

TEST(Fmf, FullRankReconstructsWithinFloatError) {
  Btf b = random_btf(make_desc(10, 9, 4, 3), 36, 0.9, 0.0, 0.0, 1);  // 36 rows x 90 texels, full rank
  auto m = encode_spec(b, "fmf:rank=36:precision=float");
  Btf out;
  ASSERT_TRUE(m->decode_all(out).ok());
  const double rel = std::sqrt(sq_error(b, out) / as_matrix(b).squaredNorm());
  EXPECT_LT(rel, 2e-6);
  EXPECT_EQ(stat(*m, "rank.rgb"), 36);
}

TEST(Fmf, ExactPathMeetsEckartYoung) {
  Btf b = random_btf(make_desc(12, 10, 5, 3), 40, 0.85, 0.01, 0.3, 2);  // 45 x 120
  const Eigen::VectorXd s = singular_values(b);
  for (int C : {1, 4, 10, 20}) {
    auto m = encode_spec(b, "fmf:svd=exact:precision=float:rank=" + std::to_string(C));
    Btf out;
    ASSERT_TRUE(m->decode_all(out).ok());
    const double optimum = s.tail(s.size() - C).squaredNorm();
    const double err = sq_error(b, out);
    EXPECT_NEAR(err / optimum, 1.0, 1e-4) << "rank " << C;
    // The model's own error report agrees with the measured error.
    EXPECT_NEAR(stat(*m, "rel_error.rgb"), std::sqrt(err / as_matrix(b).squaredNorm()), 1e-4);
  }
}

TEST(Fmf, ExactPathFewTexelsUsesTheOtherGram) {
  Btf b = random_btf(make_desc(3, 2, 6, 4), 6, 0.7, 0.05, 0.0, 3);  // 72 rows x 6 texels: n < m
  const Eigen::VectorXd s = singular_values(b);
  auto m = encode_spec(b, "fmf:svd=exact:precision=float:rank=3");
  Btf out;
  ASSERT_TRUE(m->decode_all(out).ok());
  EXPECT_NEAR(sq_error(b, out) / s.tail(s.size() - 3).squaredNorm(), 1.0, 1e-4);
}

TEST(Fmf, RandomizedWithinOnePercentOfOptimum) {
  Btf b = random_btf(make_desc(48, 48, 9, 4), 100, 0.93, 0.002, 0.1, 4);  // 108 x 2304
  const Eigen::VectorXd s = singular_values(b);
  for (int C : {8, 16, 32}) {
    auto m = encode_spec(b, "fmf:svd=randomized:oversample=16:power_iters=4:precision=float:rank=" + std::to_string(C));
    EXPECT_EQ(note(*m, "svd.rgb"), "randomized");
    Btf out;
    ASSERT_TRUE(m->decode_all(out).ok());
    const double ratio = std::sqrt(sq_error(b, out) / s.tail(s.size() - C).squaredNorm());
    EXPECT_GE(ratio, 1.0 - 1e-4) << "cannot beat Eckart-Young";
    EXPECT_LE(ratio, 1.01) << "rank " << C;
  }
}

TEST(Fmf, RandomizedIsDeterministicPerSeed) {
  Btf b = random_btf(make_desc(40, 40, 9, 4), 60, 0.9, 0.01, 0.0, 5);
  auto a1 = encode_spec(b, "fmf:svd=randomized:rank=8:power_iters=1", 11), a2 = encode_spec(b, "fmf:svd=randomized:rank=8:power_iters=1", 11);
  Btf o1, o2;
  ASSERT_TRUE(a1->decode_all(o1).ok());
  ASSERT_TRUE(a2->decode_all(o2).ok());
  EXPECT_EQ(sq_error(o1, o2), 0.0);
}

TEST(Fmf, TargetErrorPicksTheSmallestSufficientRank) {
  Btf b = random_btf(make_desc(12, 10, 5, 3), 40, 0.85, 0.0, 0.0, 6);
  const Eigen::VectorXd s = singular_values(b);
  const double total = s.squaredNorm(), target = 0.05;
  auto m = encode_spec(b, "fmf:svd=exact:precision=float:rank=45:target_error=0.05");
  const int C = int(stat(*m, "rank.rgb"));
  EXPECT_LE(std::sqrt(s.tail(s.size() - C).squaredNorm() / total), target);
  EXPECT_GT(std::sqrt(s.tail(s.size() - C + 1).squaredNorm() / total), target);
  auto capped = encode_spec(b, "fmf:svd=exact:precision=float:rank=2:target_error=0.0001");
  EXPECT_EQ(stat(*capped, "rank.rgb"), 2);
  EXPECT_NE(note(*capped, "target.rgb").find("not reached"), std::string::npos);
}

TEST(Fmf, HalfStorageErrorIsHalfPrecision) {
  Btf b = random_btf(make_desc(16, 16, 6, 3), 8, 0.8, 0.0, 0.5, 7);  // rank 8 + the offset = rank 9
  auto f = encode_spec(b, "fmf:rank=9:precision=float"), h = encode_spec(b, "fmf:rank=9:precision=half");
  Btf of, oh;
  ASSERT_TRUE(f->decode_all(of).ok());
  ASSERT_TRUE(h->decode_all(oh).ok());
  const double norm = as_matrix(b).squaredNorm();
  const double ef = std::sqrt(sq_error(b, of) / norm), eh = std::sqrt(sq_error(b, oh) / norm);
  std::printf("relative error: float %.3g, half %.3g\n", ef, eh);
  EXPECT_LT(ef, 1e-6);
  // Half keeps 11 significant bits: 2^-11 = 4.9e-4 per value, ~2e-4 RMS after the sum over
  // components. Two-sided, so a silent switch to float (or to something coarser) fails.
  EXPECT_LE(eh, 3.9e-4);
  EXPECT_GE(eh, 0.75 * 3.9e-4);
  EXPECT_LT(h->payload_bytes(), f->payload_bytes());
}

TEST(Fmf, ExtremesZerosConstantsOneTexelOneDirection) {
  // All zeros: one zero component, exact zeros back, nothing non-finite.
  Btf z = Btf::create(make_desc(6, 5, 3, 2)).value();
  auto mz = encode_spec(z, "fmf:rank=4");
  Btf oz;
  ASSERT_TRUE(mz->decode_all(oz).ok());
  for (size_t i = 0; i < oz.size(); ++i) ASSERT_EQ(oz.data()[i], 0.0f);
  EXPECT_EQ(stat(*mz, "rank.rgb"), 1);
  EXPECT_NE(note(*mz, "clamped.rgb").find("clamped to 1"), std::string::npos);
  // Constant: rank 1 reproduces it; asking for more is clamped and reported.
  Btf c = Btf::create(make_desc(6, 5, 3, 2)).value();
  for (size_t i = 0; i < c.size(); ++i) c.data()[i] = 0.37f;
  auto mc = encode_spec(c, "fmf:rank=10:precision=float");
  Btf oc;
  ASSERT_TRUE(mc->decode_all(oc).ok());
  for (size_t i = 0; i < oc.size(); ++i) ASSERT_NEAR(oc.data()[i], 0.37f, 1e-6);
  EXPECT_EQ(stat(*mc, "rank.rgb"), 1);
  // One texel, one direction (a 3 x 1 matrix).
  Btf one = Btf::create(make_desc(1, 1, 1, 1)).value();
  one.data()[0] = 0.2f, one.data()[1] = 0.5f, one.data()[2] = 0.9f;
  for (const char* spec : {"fmf:rank=5:precision=float", "fmf:rank=5:color=dfmf:precision=float"}) {
    auto m1 = encode_spec(one, spec);
    float v[3];
    m1->eval(0, 0, 0, 0, v);
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(v[k], one.data()[k], 2e-6) << spec;
  }
}

TEST(Fmf, HdrRangeSurvivesHalfStorage) {
  // Values log-uniform in [1e-6, 1e6] on a rank-2 structure (per-texel scale x per-row pattern).
  BtfDesc d = make_desc(16, 16, 5, 3);
  d.hdr = true;
  Btf b = Btf::create(d).value();
  std::mt19937 rng(8);
  std::uniform_real_distribution<double> u(-6, 6);
  const size_t m = d.abrdf_size();
  std::vector<double> row(m);
  for (auto& r : row) r = 0.5 + std::uniform_real_distribution<double>(0, 1)(rng);
  for (size_t t = 0; t < d.num_texels(); ++t) {
    const double s = std::pow(10.0, u(rng));
    for (size_t i = 0; i < m; ++i) b.abrdf(t)[i] = float(s * row[i]);
  }
  double vmax = 0;
  for (size_t i = 0; i < b.size(); ++i) vmax = std::max(vmax, double(b.data()[i]));
  for (const char* spec : {"fmf:rank=4:precision=half", "fmf:rank=4:color=dfmf:precision=half:offset=1e-5"}) {
    const bool dfmf = std::string(spec).find("dfmf") != std::string::npos;
    auto mdl = encode_spec(b, spec);
    Btf out;
    ASSERT_TRUE(mdl->decode_all(out).ok());
    double worst_rel = 0, worst_abs = 0;
    for (size_t i = 0; i < out.size(); ++i) {
      ASSERT_TRUE(std::isfinite(out.data()[i])) << spec;
      const double e = std::fabs(out.data()[i] - b.data()[i]);
      worst_abs = std::max(worst_abs, e);
      worst_rel = std::max(worst_rel, e / (double(b.data()[i]) + 1e-5));  // eps: DFMF's log offset
    }
    // rgb: an SVD's error is absolute, relative to the largest values (half: ~1e-3 of them);
    // dfmf's log luminance keeps every value relatively accurate across 12 decades.
    std::printf("%s: worst |err| / max %.3g, worst relative %.3g\n", spec, worst_abs / vmax, worst_rel);
    if (dfmf) {
      // log(1e6 + eps) = 13.8 stored in half: 2^-11 relative -> ~0.7 % relative error.
      EXPECT_LT(worst_rel, 1e-2) << spec;
      EXPECT_GE(worst_rel, 0.75e-2) << spec;  // two-sided: the half rounding is really there
    } else {
      EXPECT_LE(worst_abs / vmax, 5e-4) << spec;
      EXPECT_GE(worst_abs / vmax, 0.75 * 5e-4) << spec;
      EXPECT_GT(worst_rel, 0.5) << "rgb cannot keep 1e-6 texels next to 1e6 ones; if it now can, tighten this test";
    }
  }
}

TEST(Fmf, DfmfAutoOffsetScalesWithTheData) {
  // The automatic offset e = sum Y^2 / sum Y scales with the data, down to 1e-6-size values (it
  // used to stop at Bonn's 1e-5, which dwarfed such luminances: Y' = log(Y + e) then barely
  // moved and its half floats' steps made 13-27 % errors). A BTF times 1e-6 and times 1e6 shift
  // Y' by -+13.8 alike, so their half-stored models err alike.
  Btf base = random_btf(make_desc(8, 8, 5, 4), 3, 0.7, 0.0, 2.0, 12);
  for (size_t i = 0; i < base.size(); ++i) base.data()[i] = std::fabs(base.data()[i]);
  double err[3], e[3];
  const double scales[3] = {1e-6, 1.0, 1e6};
  for (int k = 0; k < 3; ++k) {
    Btf b = base;
    for (size_t i = 0; i < b.size(); ++i) b.data()[i] = float(double(base.data()[i]) * scales[k]);
    auto m = encode_spec(b, "fmf:color=dfmf:rank=16:chroma_rank=16");
    const std::string& spec = m->spec();
    const size_t at = spec.find("offset=");
    ASSERT_NE(at, std::string::npos) << spec;
    e[k] = std::atof(spec.c_str() + at + 7);
    Btf out;
    ASSERT_TRUE(m->decode_all(out).ok());
    err[k] = std::sqrt(sq_error(b, out) / as_matrix(b).squaredNorm());
    std::printf("scale %g: offset %.6g, relative L2 %.4g\n", scales[k], e[k], err[k]);
  }
  EXPECT_NEAR(e[0] / e[1], 1e-6, 1e-11);
  EXPECT_NEAR(e[2] / e[1], 1e6, 1e-1);
  EXPECT_GE(err[0], 0.75 * err[2]);
  EXPECT_LE(err[0], err[2] / 0.75);
}

TEST(Fmf, ValuesNearTheFloatRangeEncodeOrFailClearly) {
  // Past 1e30 the automatic dfmf offset (e = sum Y^2 / sum Y, at most the largest luminance) used
  // to fail the parameter's range ("offset=2.6e+31 is outside [0, 1e+30]"); it now scales with the
  // data up to the largest float. compare_btf sums in double: float norms overflow at this size.
  Btf base = random_btf(make_desc(8, 8, 5, 4), 3, 0.7, 0.0, 2.0, 12);
  for (size_t i = 0; i < base.size(); ++i) base.data()[i] = std::fabs(base.data()[i]);
  double e[2], err[2];
  const double scales[2] = {1.0, 1e32};
  for (int k = 0; k < 2; ++k) {
    Btf b = base;
    for (size_t i = 0; i < b.size(); ++i) b.data()[i] = float(double(base.data()[i]) * scales[k]);
    // Float storage: half-stored Y' = log(Y + e) keeps 2^-11 of |log s| (2.9 % at s = 1e32; the
    // known limit of half storage far from 1), which is not what this checks.
    auto m = encode_spec(b, "fmf:color=dfmf:rank=16:chroma_rank=16:precision=float");
    ASSERT_TRUE(m);
    const size_t at = m->spec().find("offset=");
    ASSERT_NE(at, std::string::npos) << m->spec();
    e[k] = std::atof(m->spec().c_str() + at + 7);
    Btf out;
    ASSERT_TRUE(m->decode_all(out).ok());
    err[k] = compare_btf(b, out, false).value().rel_l2;
    std::printf("scale %g: offset %.9g, relative L2 %.4g\n", scales[k], e[k], err[k]);
  }
  EXPECT_NEAR(e[1] / e[0], 1e32, 1e32 * 1e-6);
  // Not the same error: Y' is shifted by log s = 73.7, whose float rounding the SVD then carries
  // (3.2e-6 at s = 1 against 7.9e-5 here); a model, finite and within 1e-3, is what is asked.
  EXPECT_LT(err[1], 1e-3);
  EXPECT_EQ(dfmf_auto_offset(1.0, 1e300), k_dfmf_max_offset);  // the ceiling: the spec's range holds it

  // Factors past the float range are an error, not a model that decodes to infinities: the
  // singular values reach the data's norm (here ~1e39 from values near 1e37).
  Btf huge = base;
  for (size_t i = 0; i < huge.size(); ++i) huge.data()[i] = float(double(base.data()[i]) * 1e37);
  for (const char* spec : {"fmf:rank=4", "fmf:rank=4:svd=randomized", "fmf:rank=4:precision=float"}) {
    auto r = resolve_spec(spec);
    ASSERT_TRUE(r.ok());
    Context ctx;
    auto m = r->first->encode(huge, r->second, ctx);
    ASSERT_FALSE(m.ok()) << spec;
    EXPECT_EQ(m.status().code(), StatusCode::unsupported) << spec;
    EXPECT_NE(m.status().message().find("overflow float"), std::string::npos) << m.status().message();
  }
  // dfmf: luminance + offset past the largest float (both near 3e38) overflows the conversion:
  // the exact path's factors, the randomized path's first pass.
  Btf top = Btf::create(make_desc(4, 4, 3, 3)).value();
  for (size_t i = 0; i < top.size(); ++i) top.data()[i] = 3e38f;
  for (const char* spec : {"fmf:color=dfmf:rank=2", "fmf:color=dfmf:rank=2:svd=randomized"}) {
    auto r = resolve_spec(spec);
    ASSERT_TRUE(r.ok());
    Context ctx;
    auto m = r->first->encode(top, r->second, ctx);
    ASSERT_FALSE(m.ok()) << spec;
    EXPECT_TRUE(m.status().message().find("overflow float") != std::string::npos ||
                m.status().message().find("luminance + offset pass the float range") != std::string::npos)
        << m.status().message();
  }
}

TEST(Fmf, NonFiniteInputIsAnError) {
  // Small matrices (the exact path) are checked before the SVD (fmf.cpp), rgb and dfmf alike.
  for (const char* spec : {"fmf", "fmf:color=dfmf", "fmf:color=dfmf:offset=0.5"})
    for (float bad : {NAN, INFINITY, -INFINITY})
      for (size_t at : {size_t(0), size_t(17), size_t(4 * 4 * 2 * 2 * 3 - 1)}) {
        Btf b = random_btf(make_desc(4, 4, 2, 2), 2, 0.5, 0.0, 0.0, 9);
        b.data()[at] = bad;
        auto r = resolve_spec(spec);
        Context ctx;
        auto m = r->first->encode(b, r->second, ctx);
        ASSERT_FALSE(m.ok()) << spec << " " << bad << " at " << at;
        EXPECT_NE(m.status().message().find("non-finite"), std::string::npos) << m.status().message();
      }
  // The randomized paths check in their first pass (no read of their own first): rgb through
  // both schemes (truncated_svd), color=dfmf streamed (its channel SVDs, ooc_svd.h) with and
  // without its own offset. NaN and +-inf in each colour channel at the first, a middle and the
  // last value: the texel named, and the light, view and channel too unless a dfmf encode
  // converted the input in place (Context::consumable). Finite extremes pass rgb. (The data's small
  // side, 72 rows, is above rank + oversample: svd=randomized runs.)
  const BtfDesc rd = make_desc(12, 10, 6, 4);
  for (const char* spec : {"fmf:svd=randomized:rank=3:oversample=4", "fmf:svd=randomized:rank=3:oversample=4:power_iters=0",
                           "fmf:color=dfmf:svd=randomized:rank=3:chroma_rank=2:oversample=4",
                           "fmf:color=dfmf:svd=randomized:rank=3:chroma_rank=2:oversample=4:offset=0.5"}) {
    auto r = resolve_spec(spec);
    ASSERT_TRUE(r.ok());
    const bool dfmf = std::string(spec).find("dfmf") != std::string::npos;
    for (float bad : {NAN, INFINITY, -INFINITY})
      for (size_t at : {size_t(0), size_t(778), size_t(12 * 10 * 72 - 1)})
        for (bool consume : {false, true}) {
          Btf b = random_btf(rd, 2, 0.5, 0.0, 1.0, 9);
          b.data()[at] = bad;
          Context ctx;
          if (consume) ctx.consumable = &b;
          auto m = r->first->encode(b, r->second, ctx);
          ASSERT_FALSE(m.ok()) << spec << " " << bad << " at " << at;
          EXPECT_EQ(m.status().code(), StatusCode::corrupt_data);
          const size_t texel = at / 72;
          const std::string where = "at texel (" + std::to_string(texel % 12) + ", " + std::to_string(texel / 12) + ")";
          EXPECT_NE(m.status().message().find("fmf input: non-finite value"), std::string::npos) << m.status().message();
          EXPECT_NE(m.status().message().find(where), std::string::npos) << consume << ": " << m.status().message();
          if (!(dfmf && consume)) {
            EXPECT_NE(m.status().message().find(", channel " + std::to_string(at % 3)), std::string::npos) << m.status().message();
          }
        }
    if (dfmf) continue;
    // Finite extremes are no non-finite input: 2e38 and -2e38 in one texel (the norm, 2.8e38, a
    // float), and a denormal, encode; 3.4e38 and -3.4e38 there make a singular value of 4.8e38,
    // past the float range: refused as such (block_from_svd), not as a non-finite value.
    Btf ok = random_btf(rd, 2, 0.5, 0.0, 1.0, 9);
    ok.data()[5] = 2e38f, ok.data()[6] = -2e38f, ok.data()[7] = 1e-45f;
    Context ctx;
    EXPECT_TRUE(r->first->encode(ok, r->second, ctx).ok()) << spec;
    ok.data()[5] = 3.4e38f, ok.data()[6] = -3.4e38f;
    auto over = r->first->encode(ok, r->second, ctx);
    ASSERT_FALSE(over.ok()) << spec;
    EXPECT_EQ(over.status().code(), StatusCode::unsupported) << over.status().message();
    EXPECT_NE(over.status().message().find("overflow float"), std::string::npos) << over.status().message();
  }
  // The SVD's contract (svd.h) on its own: randomized (block Krylov and power iterations) refuses
  // a non-finite matrix; the exact method does not check.
  {
    std::vector<float> B(60 * 50, 0.25f);
    for (size_t i = 0; i < B.size(); ++i) B[i] += float(i % 7) * 0.1f + float(i % 11) * 0.01f;
    B[1234] = NAN;
    SvdOptions o;
    o.max_rank = 3, o.oversample = 4, o.method = SvdMethod::randomized;
    EXPECT_TRUE(svd_checks_finite(60, 50, o));
    for (RandomizedScheme sch : {RandomizedScheme::block_krylov, RandomizedScheme::power}) {
      o.scheme = sch;
      auto res = truncated_svd(B.data(), 60, 50, o);
      ASSERT_FALSE(res.ok());
      EXPECT_EQ(res.status().code(), StatusCode::corrupt_data);
    }
    o.method = SvdMethod::exact;
    EXPECT_FALSE(svd_checks_finite(60, 50, o));
  }
  // The moments' flag (fmf.h): set by a NaN or inf value, not by finite extremes.
  const float big = 3.4e38f, tiny = 1e-38f, vals[2][6] = {{big, big, big, tiny, 0.f, -big}, {1.f, NAN, 1.f, 1.f, 1.f, 1.f}};
  double sy = 0, sy2 = 0;
  EXPECT_FALSE(dfmf_luminance_moments(vals[0], 2, &sy, &sy2));
  EXPECT_TRUE(dfmf_luminance_moments(vals[1], 2, &sy, &sy2));
}

TEST(Fmf, DfmfFullRankRoundTrip) {
  Btf b = random_btf(make_desc(8, 8, 4, 3), 4, 0.8, 0.0, 2.0, 10);  // offset keeps values positive
  for (size_t i = 0; i < b.size(); ++i) b.data()[i] = std::fabs(b.data()[i]);
  auto m = encode_spec(b, "fmf:color=dfmf:rank=12:precision=float");
  Btf out;
  ASSERT_TRUE(m->decode_all(out).ok());
  EXPECT_LT(std::sqrt(sq_error(b, out) / as_matrix(b).squaredNorm()), 1e-5);
}

TEST(Fmf, RegionAndDirectionSubsetMatchFullDecode) {
  Btf b = random_btf(make_desc(9, 7, 5, 4), 6, 0.8, 0.01, 1.0, 11);
  for (const char* spec : {"fmf:rank=5", "fmf:rank=5:color=dfmf"}) {
    auto m = encode_spec(b, spec);
    Btf full, part;
    ASSERT_TRUE(m->decode_all(full).ok());
    DecodeRequest q;
    q.x0 = 2, q.y0 = 3, q.width = 5, q.height = 3;
    q.lights = {4, 1};
    q.views = {2};
    ASSERT_TRUE(m->decode(q, part).ok());
    ASSERT_EQ(part.desc().width, 5);
    for (int y = 0; y < 3; ++y)
      for (int x = 0; x < 5; ++x)
        for (int l = 0; l < 2; ++l)
          for (int c = 0; c < 3; ++c) {
            float v[3];
            m->eval(2 + x, 3 + y, q.lights[l], 2, v);
            ASSERT_NEAR(part.at(x, y, l, 0, c), full.at(2 + x, 3 + y, q.lights[l], 2, c), 1e-5f) << spec;
            ASSERT_NEAR(v[c], full.at(2 + x, 3 + y, q.lights[l], 2, c), 1e-5f) << spec;
          }
  }
}

TEST(Fmf, InterpolationIsExactAtMeasuredDirections) {
  BtfDesc d = make_desc(4, 3, 1, 1);
  d.lights = DirectionSet::ubo2003();
  d.views = DirectionSet::ubo2014();
  d.views.dirs.resize(19);  // first three rings of UBO2014
  d.views.name = "custom";
  Btf b = random_btf(d, 5, 0.8, 0.01, 1.0, 12);
  auto m = encode_spec(b, "fmf:rank=5");
  for (int l : {0, 7, 80})
    for (int v : {0, 5, 18}) {
      float a[3], e[3];
      m->eval(3, 2, l, v, e);
      ASSERT_TRUE(m->eval_dir(3, 2, d.lights.dirs[l], d.views.dirs[v], a).ok());
      for (int c = 0; c < 3; ++c) EXPECT_EQ(a[c], e[c]);
    }
  // Between directions the value is a convex blend of the 9 measured neighbours.
  float a[3];
  ASSERT_TRUE(m->eval_dir(1, 1, dir_from_theta_phi(0.4, 0.3), dir_from_theta_phi(0.2, 1.0), a).ok());
  for (float x : a) EXPECT_TRUE(std::isfinite(x));
  EXPECT_FALSE(m->eval_dir(4, 0, d.lights.dirs[0], d.views.dirs[0], a).ok());
}

TEST(Fmf, SaveLoadRoundTripIsExactAndByteStable) {
  Btf b = random_btf(make_desc(7, 5, 4, 3), 6, 0.8, 0.01, 1.0, 13);
  for (const char* spec : {"fmf:rank=4:precision=half", "fmf:rank=4:precision=float:color=dfmf"}) {
    auto m = encode_spec(b, spec);
    const std::string p1 = tmp_path("a.btfc"), p2 = tmp_path("b.btfc");
    ASSERT_TRUE(save_model(*m, *find_codec("fmf"), p1).ok());
    auto rd = ContainerReader::open(p1);
    ASSERT_TRUE(rd.ok()) << rd.status().message();
    EXPECT_EQ(rd->codec().spec, m->spec());
    auto loaded = load_model(rd.value());
    ASSERT_TRUE(loaded.ok()) << loaded.status().message();
    Btf o1, o2;
    ASSERT_TRUE(m->decode_all(o1).ok());
    ASSERT_TRUE(loaded.value()->decode_all(o2).ok());
    EXPECT_EQ(sq_error(o1, o2), 0.0) << spec;
    // save -> load -> save is byte-identical apart from the encode statistics chunk, which a
    // loaded model does not have; compare the tensors.
    ASSERT_TRUE(save_model(*loaded.value(), *find_codec("fmf"), p2).ok());
    auto rd2 = ContainerReader::open(p2);
    ASSERT_TRUE(rd2.ok());
    ASSERT_EQ(rd2->tensors().size(), rd->tensors().size());
    for (const auto& t : rd->tensors()) {
      auto x = rd->read(t.name), y = rd2->read(t.name);
      ASSERT_TRUE(x.ok() && y.ok());
      EXPECT_EQ(x->bytes, y->bytes) << t.name;
    }
    std::remove(p1.c_str());
    std::remove(p2.c_str());
  }
}
