// Tests of the streamed color=dfmf and svd=exact paths: each against its in-core counterpart,
// three simulated processes against one, failures reaching every process, and the refusal of a
// Gram matrix that does not fit the limit.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>
#include <cstring>
#include <functional>
#include <random>
#include <thread>

#include "codecs/codec.h"
#include "codecs/fmf/fmf.h"
#include "codecs/fmf/fmf_model.h"
#include "codecs/fmf/ooc_dfmf.h"
#include "codecs/fmf/ooc_fmf.h"
#include "core/chunks.h"
#include "core/svd.h"
#include "tests/ooc_test_util.h"

using namespace btfc;
using namespace btfc::ooc_test;

namespace {

double stat(const Model& m, const std::string& key) {
  for (const auto& [k, v] : m.stats().numbers)
    if (k == key) return v;
  ADD_FAILURE() << "no stat " << key;
  return -1;
}

// A BTF with some negative luminance (HDR noise), so the clamp count means something.
Btf noisy(int w, int h) {
  Btf b = synth(w, h);
  for (size_t t = 0; t < b.desc().num_texels(); t += 7)
    for (int c = 0; c < 3; ++c) b.abrdf(t)[3 * (t % b.desc().num_images()) + size_t(c)] = -0.02f;
  return b;
}

// encode_fmf_streamed over `p` thread-simulated processes; returns process 0's result.
Result<StreamedEncode> encode_on(int p, const ChunkSource& src, const Btf& b, const Params& params) {
  std::vector<Result<StreamedEncode>> res;
  for (int r = 0; r < p; ++r) res.emplace_back(Status{});
  run_group(p, [&](Collective& me, int r) {
    Context ctx;
    res[size_t(r)] = encode_fmf_streamed(src, b.desc(), params, ctx, me);
  });
  for (int r = 1; r < p; ++r) {
    if (!res[size_t(r)].ok()) return res[size_t(r)].status();
    EXPECT_FALSE(res[size_t(r)]->model) << "only process 0 builds the model";
  }
  return std::move(res[0]);
}

// ||A - B|| / ||A|| of two models' decoded BTFs.
double model_difference(const Model& a, const Model& b) {
  Btf x, y;
  EXPECT_TRUE(a.decode_all(x).ok() && b.decode_all(y).ok());
  Eigen::Map<const Eigen::VectorXf> X(x.data(), Eigen::Index(x.size())), Y(y.data(), Eigen::Index(y.size()));
  return (X - Y).cast<double>().norm() / X.cast<double>().norm();
}

}  // namespace

TEST(StreamingDfmf, MatchesInCoreDfmfFromCopiedAndMappedChunks) {
  const Btf b = noisy(20, 18);  // 162 images x 360 texels
  auto spec = resolve_spec("fmf:color=dfmf:rank=10:chroma_rank=6:oversample=8:power_iters=3:svd=randomized");
  ASSERT_TRUE(spec.ok());
  Context ctx;
  auto in_core = spec->first->encode(b, spec->second, ctx);
  ASSERT_TRUE(in_core.ok()) << in_core.status().message();
  const double e_in = model_error(b, *in_core.value());
  EXPECT_GT(e_in, 0.002);  // not exact at these ranks: the comparison means something
  // In core, randomized dfmf runs the one-stream path too (over the Btf's memory): each channel
  // within 1 % of its Eckart-Young optimum, the exact SVD's error at the same rank.
  auto exact_spec = resolve_spec("fmf:color=dfmf:rank=10:chroma_rank=6:svd=exact");
  ASSERT_TRUE(exact_spec.ok());
  auto exact = exact_spec->first->encode(b, exact_spec->second, ctx);
  ASSERT_TRUE(exact.ok()) << exact.status().message();
  for (const char* ch : {"y", "u", "v"}) {
    const double got = stat(*in_core.value(), std::string("rel_error.") + ch), best = stat(*exact.value(), std::string("rel_error.") + ch);
    EXPECT_GT(best, 0.001) << ch;
    EXPECT_GE(got, best * (1 - 1e-4)) << ch;  // estimates from energies: equal up to rounding at best
    EXPECT_LE(got, best * 1.01) << ch;
  }
  for (bool mapped : {false, true}) {
    MemorySource src(b, 50);  // 8 chunks, the last one short
    src.mapped = mapped;
    Collective one;
    auto st = encode_fmf_streamed(src, b.desc(), spec->second, ctx, one);
    ASSERT_TRUE(st.ok()) << st.status().message();
    const Model& m = *st->model;
    EXPECT_EQ(m.spec(), in_core.value()->spec());
    const double e_st = model_error(b, m);
    EXPECT_LT(std::fabs(e_st - e_in) / e_in, 0.01) << "mapped " << mapped << ": in core " << e_in << ", streamed " << e_st;
    // The same clamped values and ranks as in core; the three SVDs in one stream: one read of
    // the BTF per pass, as many passes as the channel with the most Krylov blocks needs (+ 1),
    // at most power_iters + 2.
    EXPECT_EQ(stat(m, "negative_luminance_clamped"), stat(*in_core.value(), "negative_luminance_clamped"));
    EXPECT_GT(stat(m, "negative_luminance_clamped"), 0);
    EXPECT_EQ(stat(m, "rank.y"), 10);
    EXPECT_EQ(stat(m, "rank.u"), 6);
    EXPECT_EQ(stat(m, "rank.v"), 6);
    const double blocks = std::max({stat(m, "krylov_blocks.y"), stat(m, "krylov_blocks.u"), stat(m, "krylov_blocks.v")});
    EXPECT_GE(blocks, 2);
    EXPECT_EQ(stat(m, "stream.passes"), blocks + 1);
    EXPECT_EQ(double(st->stats.passes), blocks + 1);
    EXPECT_LE(st->stats.passes, 3 + 2);
    EXPECT_EQ(st->stats.bytes_read, uint64_t(st->stats.passes) * b.desc().num_values() * 4);
  }
}

TEST(StreamingDfmf, AutoOffsetIsTheSampleTexelsOnEveryPath) {
  // More texels than the sample: the automatic offset is sum Y^2 / sum Y over 4096 evenly spaced
  // texels, with the same bits in core, streamed (mapped or loaded chunks), and on one or three
  // processes.
  const std::vector<size_t> few = dfmf_offset_sample(100);
  ASSERT_EQ(few.size(), 100u);
  for (size_t i = 0; i < few.size(); ++i) EXPECT_EQ(few[i], i);
  const Btf b = synth(75, 60);  // 4500 texels x 486 rows
  const size_t n = b.desc().num_texels(), rows = b.desc().num_images();
  const std::vector<size_t> s = dfmf_offset_sample(n);
  ASSERT_EQ(s.size(), 4096u);
  EXPECT_EQ(s.front(), 0u);
  EXPECT_EQ(s.back(), 4095 * n / 4096);
  for (size_t i = 1; i < s.size(); ++i) ASSERT_LT(s[i - 1], s[i]);
  // The definition, with the portable kernel; and over every texel, which the sample estimates.
  double sy = 0, sy2 = 0, ay = 0, ay2 = 0;
  for (size_t t : s) dfmf_luminance_moments_reference(b.abrdf(t), rows, &sy, &sy2);
  for (size_t t = 0; t < n; ++t) dfmf_luminance_moments_reference(b.abrdf(t), rows, &ay, &ay2);
  const double e = dfmf_auto_offset(b), want = sy2 / sy, all = ay2 / ay;
  std::printf("offset: sample %.9g, all texels %.9g\n", e, all);
  EXPECT_NEAR(e, want, 1e-12 * want);  // the kernels add in another order
  EXPECT_LT(std::fabs(e - all) / all, 0.01);
  EXPECT_NE(e, all);  // a sample, not every texel
  for (bool mapped : {false, true}) {
    MemorySource src(b, 700);  // 7 chunks, the last one short
    src.mapped = mapped;
    for (int P : {1, 3}) {
      std::vector<double> got(size_t(P), -1.0);
      run_group(P, [&](Collective& me, int r) {
        auto o = DfmfChannelSource::auto_offset(src, owned_chunks(src, r, P), me);
        if (o.ok()) got[size_t(r)] = *o;
      });
      for (double g : got) EXPECT_EQ(g, e) << "mapped " << mapped << ", " << P << " processes";
    }
  }
  // The in-core encode uses that offset.
  auto spec = resolve_spec("fmf:color=dfmf:rank=2:chroma_rank=1:svd=randomized:oversample=2:power_iters=0");
  ASSERT_TRUE(spec.ok());
  Context ctx;
  auto m = spec->first->encode(b, spec->second, ctx);
  ASSERT_TRUE(m.ok()) << m.status().message();
  EXPECT_NEAR(stat(*m.value(), "dfmf_offset"), e, 1e-5 * e);  // the spec keeps 6 digits; all texels: 1.6e-3 off
}

// The vectorized transform (dfmf_channels: a polynomial log) against the definition in double:
// Y' = log(max(Y, 0) + e), U' = U / (max(Y, 0) + e), V' likewise; over HDR values 1e-6..1e6,
// negatives, zeros, and sums that are not normal floats (a denormal offset, inf, NaN), which
// take std::log. dfmf_channel returns the same bits per channel.
TEST(StreamingDfmf, VectorizedTransformIsTheDefinition) {
  Eigen::Matrix3d rgb_from_yuv;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) rgb_from_yuv(i, j) = fmf::k_rgb_from_yuv[i][j];
  const Eigen::Matrix3d M = rgb_from_yuv.inverse();  // YUV from RGB, as the codec derives it
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> ex(-6.f, 6.f), sg(-1.f, 1.f);
  const size_t rows = 1000;
  std::vector<float> rgb(3 * rows);
  for (size_t i = 0; i < rgb.size(); ++i) rgb[i] = (sg(rng) < -0.8f ? -1.f : 1.f) * std::pow(10.f, ex(rng));
  for (size_t i = 0; i < 30; ++i) rgb[i] = 0.f;  // zero luminance: log(offset)
  for (float offset : {0.19f, 1e-5f, 1e-40f /* denormal */}) {
    std::vector<float> y(rows), u(rows), v(rows);
    const size_t clamped = dfmf_channels(rgb.data(), rows, offset, y.data(), u.data(), v.data());
    size_t want_clamped = 0;
    for (size_t r = 0; r < rows; ++r) {
      const float* p = &rgb[3 * r];
      double l = M(0, 0) * p[0] + M(0, 1) * p[1] + M(0, 2) * p[2];
      if (l < 0) l = 0, ++want_clamped;
      const double d = l + double(offset);
      // The log's own error, plus the float rounding of Y's sum (cancelling terms), divided by d.
      const double mag = (std::fabs(p[0]) + std::fabs(p[1]) + std::fabs(p[2])) / d;
      ASSERT_NEAR(y[r], std::log(d), 4e-7 * std::max(1.0, std::fabs(std::log(d))) + 3e-7 * mag) << "row " << r << " offset " << offset;
      const double want_u = (M(1, 0) * p[0] + M(1, 1) * p[1] + M(1, 2) * p[2]) / d;
      if (std::fabs(want_u) < 1e37) {
        EXPECT_NEAR(u[r], want_u, 1e-6 * mag) << "row " << r;  // else float overflow, as before
      }
    }
    EXPECT_EQ(clamped, want_clamped);
    EXPECT_GT(clamped, 0u);
    for (int k = 0; k < 3; ++k) {
      std::vector<float> one(rows);
      EXPECT_EQ(dfmf_channel(rgb.data(), rows, k, offset, one.data()), clamped);
      EXPECT_EQ(one, k == 0 ? y : k == 1 ? u : v) << "channel " << k;
    }
  }
  // The largest floats (luminance ~ FLT_MAX), inf and NaN: log(FLT_MAX); std::log's inf and
  // NaN, not a polynomial's number.
  const float big = std::numeric_limits<float>::max(), inf = std::numeric_limits<float>::infinity(),
              nan = std::numeric_limits<float>::quiet_NaN();
  const float odd[9] = {big, big, big, inf, inf, inf, nan, 1.f, 1.f};
  float y[3], u[3], v[3];
  dfmf_channels(odd, 3, 0.19f, y, u, v);
  EXPECT_NEAR(y[0], std::log(double(big)), 1e-4);
  EXPECT_TRUE(std::isinf(y[1]) && y[1] > 0);
  EXPECT_TRUE(std::isnan(y[2]));
}

// This CPU's kernels (AVX-512 or AVX2, by hand; the AVX2 ones also on AVX-512 CPUs) against the portable builds:
// the channels bit for bit, the moments to rounding and the same flag, for every length's tail
// (0-40 rows) and a texel's 6561, over HDR values with negatives, zeros, denormals, inf and NaN.
TEST(StreamingDfmf, ChannelKernelsMatchThePortableBuild) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> ex(-6.f, 6.f), u01(0.f, 1.f);
  const float special[] = {0.f, -0.f, 1e-40f, -1e-40f, std::numeric_limits<float>::infinity(), -std::numeric_limits<float>::infinity(),
                           std::numeric_limits<float>::quiet_NaN(), 3.4e38f};
  std::vector<size_t> lengths;
  for (size_t n = 0; n <= 40; ++n) lengths.push_back(n);
  lengths.push_back(6561);
  for (int odd = 0; odd < 2; ++odd)
    for (size_t rows : lengths) {
      std::vector<float> rgb(3 * rows);
      for (float& x : rgb) x = (u01(rng) < 0.1f ? -1.f : 1.f) * std::pow(10.f, ex(rng));
      if (odd)  // a few special values where the vector loop or the tail reads them
        for (size_t i = 0; i < rgb.size(); i += 7) rgb[i] = special[(i / 7) % 8];
      for (float offset : {0.19f, 1e-5f, 1e-40f}) {
        std::vector<float> a(3 * rows + 1), b(3 * rows + 1);
        const size_t ca = dfmf_channels(rgb.data(), rows, offset, a.data(), a.data() + rows, a.data() + 2 * rows);
        const size_t cb = dfmf_channels_reference(rgb.data(), rows, offset, b.data(), b.data() + rows, b.data() + 2 * rows);
        EXPECT_EQ(ca, cb) << rows << " rows, offset " << offset;
        ASSERT_EQ(std::memcmp(a.data(), b.data(), a.size() * sizeof(float)), 0) << rows << " rows, offset " << offset << ", odd " << odd;
        size_t c2 = 0;  // the AVX2 kernel too where it runs (an AVX-512 CPU takes its own above)
        std::fill(a.begin(), a.end() - 1, -7.f);  // not the guard value past the channels
        if (dfmf_channels_avx2(rgb.data(), rows, offset, a.data(), a.data() + rows, a.data() + 2 * rows, &c2)) {
          EXPECT_EQ(c2, cb) << rows << " rows, offset " << offset << " (AVX2)";
          ASSERT_EQ(std::memcmp(a.data(), b.data(), a.size() * sizeof(float)), 0) << rows << " rows, offset " << offset << ", odd " << odd << " (AVX2)";
        }
      }
      double sa[2] = {0.5, 0.25}, sb[2] = {0.5, 0.25};
      const bool ba = dfmf_luminance_moments(rgb.data(), rows, &sa[0], &sa[1]);
      const bool bb = dfmf_luminance_moments_reference(rgb.data(), rows, &sb[0], &sb[1]);
      EXPECT_EQ(ba, bb) << rows << " rows, odd " << odd;
      EXPECT_EQ(bb, odd == 1 && rows >= 10) << rows << " rows";  // the inf at value 28 (row 9)
      for (int k = 0; k < 2; ++k)
        if (std::isfinite(sb[k])) {
          EXPECT_NEAR(sa[k], sb[k], 1e-12 * std::fabs(sb[k])) << rows << " rows, sum " << k;
        }
      double s2[2] = {0.5, 0.25};
      bool b2 = false;
      if (dfmf_luminance_moments_avx2(rgb.data(), rows, &s2[0], &s2[1], &b2)) {
        EXPECT_EQ(b2, bb) << rows << " rows, odd " << odd << " (AVX2)";
        for (int k = 0; k < 2; ++k)
          if (std::isfinite(sb[k])) {
            EXPECT_NEAR(s2[k], sb[k], 1e-12 * std::fabs(sb[k])) << rows << " rows, sum " << k << " (AVX2)";
          }
      }
    }
}

// The in-core one-stream path (randomized) at the extremes, against svd=exact on the same data:
// all zeros (Y' constant, U' and V' zero matrices), a constant, and HDR texels 1e-6..1e6 on a
// rank-2 pattern. The decoded BTF is finite and within 1 % (plus round-off) of the exact error.
TEST(StreamingDfmf, InCoreOneStreamHoldsAtTheExtremes) {
  const Btf base = synth(12, 10);  // 162 images x 120 texels: rank 4 + oversample 4 < 120 is randomized
  std::vector<std::pair<const char*, Btf>> cases;
  Btf zeros = base, constant = base, hdr = base;
  std::fill(zeros.data(), zeros.data() + zeros.size(), 0.0f);
  std::fill(constant.data(), constant.data() + constant.size(), 0.37f);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> ex(-6, 6), pat(0.5, 1.5);
  std::vector<double> row(hdr.desc().abrdf_size());
  for (double& r : row) r = pat(rng);
  for (size_t t = 0; t < hdr.desc().num_texels(); ++t) {
    const double s = std::pow(10.0, ex(rng));
    for (size_t i = 0; i < row.size(); ++i) hdr.abrdf(t)[i] = float(s * row[i] * (t % 2 ? 1.0 : 0.5 + 0.5 * double(i % 3)));
  }
  cases.emplace_back("zeros", std::move(zeros));
  cases.emplace_back("constant", std::move(constant));
  cases.emplace_back("hdr", std::move(hdr));
  Context ctx;
  for (auto& [name, b] : cases) {
    double err[2];
    for (int exact = 0; exact < 2; ++exact) {
      auto spec = resolve_spec(std::string("fmf:color=dfmf:rank=4:chroma_rank=2:oversample=4:power_iters=2:precision=float:svd=") +
                               (exact ? "exact" : "randomized"));
      ASSERT_TRUE(spec.ok());
      auto m = spec->first->encode(b, spec->second, ctx);
      ASSERT_TRUE(m.ok()) << name << ": " << m.status().message();
      if (!exact) {
        EXPECT_GE(stat(*m.value(), "krylov_blocks.y"), 1) << name << ": the one-stream path ran";
      }
      Btf out;
      ASSERT_TRUE(m.value()->decode_all(out).ok());
      for (size_t i = 0; i < out.size(); ++i) ASSERT_TRUE(std::isfinite(out.data()[i])) << name << " value " << i;
      double sq = 0, ref = 0;
      for (size_t i = 0; i < out.size(); ++i) {
        const double d = double(out.data()[i]) - double(b.data()[i]);
        sq += d * d, ref += double(b.data()[i]) * double(b.data()[i]);
      }
      err[exact] = std::sqrt(sq / std::max(ref, 1e-300));
      if (std::string(name) == "zeros") {
        EXPECT_LT(std::sqrt(sq / double(out.size())), 1e-6) << "zeros decode to ~0";
      }
    }
    if (std::string(name) != "zeros") {
      EXPECT_LE(err[0], err[1] * 1.01 + 1e-5) << name << ": randomized " << err[0] << ", exact " << err[1];
    }
  }
}

// Context::consumable: the in-core color=dfmf encode then converts each texel once, in the
// input's own memory, and gives the model it gives without (bit for bit). The consumed input
// has changed (the path ran); target_error, whose search compares decodes with the input, and a
// context naming another BTF leave the input as it was.
TEST(StreamingDfmf, ConsumedInputGivesTheSameModel) {
  const Btf b = noisy(12, 10);  // 162 images x 120 texels
  for (const char* text : {"fmf:color=dfmf:rank=6:chroma_rank=3:oversample=4:power_iters=2:precision=float:svd=randomized",
                           "fmf:color=dfmf:rank=6:oversample=4:power_iters=2:svd=randomized:target_error=0.05"}) {
    auto spec = resolve_spec(text);
    ASSERT_TRUE(spec.ok()) << text;
    Context keep;
    auto want = spec->first->encode(b, spec->second, keep);
    ASSERT_TRUE(want.ok()) << text << ": " << want.status().message();
    for (int named = 0; named < 2; ++named) {
      Btf in = b, other = b;
      Context eat;
      eat.consumable = named ? &in : &other;
      auto got = spec->first->encode(in, spec->second, eat);
      ASSERT_TRUE(got.ok()) << text << ": " << got.status().message();
      const auto& wb = dynamic_cast<const fmf::FmfModel&>(*want.value()).blocks();
      const auto& gb = dynamic_cast<const fmf::FmfModel&>(*got.value()).blocks();
      ASSERT_EQ(wb.size(), 3u);
      ASSERT_EQ(gb.size(), 3u);
      for (size_t k = 0; k < 3; ++k) {
        EXPECT_TRUE(wb[k].U == gb[k].U && wb[k].SxV == gb[k].SxV && wb[k].S == gb[k].S) << text << ": block " << k;
      }
      EXPECT_EQ(stat(*got.value(), "negative_luminance_clamped"), stat(*want.value(), "negative_luminance_clamped"));
      EXPECT_GT(stat(*got.value(), "negative_luminance_clamped"), 0) << "the clamp count means something";
      const bool consumed = std::memcmp(in.data(), b.data(), b.size() * sizeof(float)) != 0;
      EXPECT_EQ(consumed, named == 1 && std::strstr(text, "target_error") == nullptr) << text << ", named " << named;
      EXPECT_EQ(std::memcmp(other.data(), b.data(), b.size() * sizeof(float)), 0) << "only the named input is consumed";
    }
  }
}

// The two ways of splitting a chunk into 3 matrices of m rows (row r of matrix i in a column:
// value(column, i, r)): into part buffers (plain), and in place over `kept`, dst's memory (each
// column's matrices one after the other, through a copy). `splits` (may be null) counts both.
using SplitValue = std::function<float(const float* col, size_t i, size_t r)>;
static void set_splits(size_t m, SplitValue value, float* kept, const MatrixChunks& dst, fmf::ChunkSplit& plain, fmf::ChunkSplit& in_place,
                size_t* splits) {
  const size_t in_rows = 3 * m;
  plain.channels = in_place.channels = 3, plain.rows = in_place.rows = m;
  plain.split = [=](size_t, size_t, const float* B, size_t count, float* const* out, size_t ld) {
    if (splits) ++*splits;
    for (size_t t = 0; t < count; ++t)
      for (size_t r = 0; r < m; ++r)
        for (size_t i = 0; i < 3; ++i) out[i][t * ld + r] = value(B + t * in_rows, i, r);
  };
  in_place.in_place = [=, &dst](size_t c, size_t off) { return kept + (dst.chunk_first(c) + off) * in_rows; };
  in_place.split_in_place = [=](size_t, size_t, float* B, size_t count) {
    if (splits) ++*splits;
    std::vector<float> col(in_rows);
    for (size_t t = 0; t < count; ++t) {
      for (size_t i = 0; i < 3; ++i)
        for (size_t r = 0; r < m; ++r) col[i * m + r] = value(B + t * in_rows, i, r);
      std::copy(col.begin(), col.end(), B + t * in_rows);
    }
  };
}

// ChunkSplit::in_place over chunks and parts of several sizes: the results are those of
// splitting into part buffers in every pass, bit for bit, each part is split once (the later
// passes read it back), and each texel's column holds its matrices' columns after the stream.
TEST(StreamingDfmf, InPlaceSplitKeepsEachPartWhereItWas) {
  const Btf b = noisy(6, 5);  // 486 rows (162 x RGB) x 30 texels
  const size_t in_rows = b.desc().abrdf_size(), m = in_rows / 3, n = b.desc().num_texels();
  SvdOptions o;
  o.max_rank = 3, o.oversample = 3, o.power_iters = 2, o.method = SvdMethod::randomized;
  const std::vector<SvdOptions> opts{o, o, o};
  // Matrix i: rows i, i + 3, ... of the source, times i + 1 (a deinterleave, as the colour split).
  auto value = [&](const float* col, size_t i, size_t r) { return col[3 * r + i] * float(i + 1); };
  size_t splits = 0;
  fmf::ChunkSplit plain, in_place;
  Btf kept = b;
  const MatrixChunks src(b.data(), in_rows, n, 7), dst(kept.data(), in_rows, n, 7);
  set_splits(m, value, kept.data(), dst, plain, in_place, &splits);
  plain.part_values = in_place.part_values = 3 * m;  // parts of 3 texels: 3 + 3 + 1 in a chunk of 7
  Collective one;
  StreamStats st;
  auto want = fmf::streaming_svds(src, owned_chunks(src, 0, 1), &plain, opts, one);
  const size_t splits_plain = splits;
  splits = 0;
  auto got = fmf::streaming_svds(dst, owned_chunks(dst, 0, 1), &in_place, opts, one, &st);
  ASSERT_TRUE(want.ok() && got.ok());
  EXPECT_GE(st.passes, 3);
  EXPECT_EQ(splits, size_t(13)) << "4 chunks of 3 parts and one of 2 texels (1 part), each split once";
  EXPECT_EQ(splits_plain, splits * size_t(st.passes)) << "without: split in every pass";
  for (size_t i = 0; i < 3; ++i) {
    EXPECT_TRUE(want.value()[i].U == got.value()[i].U && want.value()[i].SxV == got.value()[i].SxV && want.value()[i].S == got.value()[i].S)
        << "matrix " << i;
  }
  for (size_t t : {size_t(0), size_t(8), n - 1})
    for (size_t i = 0; i < 3; ++i)
      for (size_t r = 0; r < m; ++r) ASSERT_EQ(kept.abrdf(t)[i * m + r], value(b.abrdf(t), i, r)) << t << ", " << i << ", " << r;
  // A split in place that does not fill the source's rows, or without its transform, is refused.
  fmf::ChunkSplit bad = in_place;
  bad.rows = m - 1;
  EXPECT_FALSE(fmf::streaming_svds(dst, owned_chunks(dst, 0, 1), &bad, opts, one).ok());
  bad = in_place;
  bad.split_in_place = nullptr;
  EXPECT_FALSE(fmf::streaming_svds(dst, owned_chunks(dst, 0, 1), &bad, opts, one).ok());
}

// From 1024 texels the first pass's sketch is sparse, and a split in place whose factorizations
// share it sums one sketch of each texel's stacked channels (streaming_svds) instead of one per
// channel: the models are those of three sketches of split parts, bit for bit, and each channel
// keeps its own energy (its error estimate), in the bucket order (150 rows) and the texel order
// (4200 rows) of the sketch.
TEST(StreamingDfmf, StackedSketchGivesEachChannelItsOwnSumsAndEnergy) {
  std::mt19937_64 rng(11);
  std::normal_distribution<float> g(0.f, 1.f);
  for (size_t m : {size_t(50), size_t(1400)}) {
    const size_t in_rows = 3 * m, n = 1100;
    // Rank 6 plus noise, each row's three values (the "channels") on their own scale.
    Eigen::MatrixXf L(Eigen::Index(in_rows), 6), R(6, Eigen::Index(n));
    for (Eigen::Index i = 0; i < L.size(); ++i) L.data()[i] = g(rng) * float(1 + i % 3);
    for (Eigen::Index i = 0; i < R.size(); ++i) R.data()[i] = g(rng) / float(1 + i % 6);
    Eigen::MatrixXf B = L * R;
    for (Eigen::Index i = 0; i < B.size(); ++i) B.data()[i] += 0.01f * g(rng);
    std::vector<float> kept(B.data(), B.data() + B.size());
    SvdOptions o;
    o.max_rank = 4, o.oversample = 4, o.power_iters = 1, o.method = SvdMethod::randomized;
    ASSERT_TRUE(make_column_sketch(n, 8, o).sparse());
    const std::vector<SvdOptions> opts{o, o, o};
    fmf::ChunkSplit plain, in_place;
    const MatrixChunks src(B.data(), in_rows, n, 300), dst(kept.data(), in_rows, n, 300);
    set_splits(m, [](const float* col, size_t i, size_t r) { return col[3 * r + i]; }, kept.data(), dst, plain, in_place, nullptr);
    plain.part_values = in_place.part_values = 200 * m;  // parts of 200 texels in chunks of 300
    Collective one;
    auto want = fmf::streaming_svds(src, owned_chunks(src, 0, 1), &plain, opts, one);
    auto got = fmf::streaming_svds(dst, owned_chunks(dst, 0, 1), &in_place, opts, one);
    ASSERT_TRUE(want.ok() && got.ok());
    for (size_t i = 0; i < 3; ++i) {
      const SvdResult &w = want.value()[i], &r = got.value()[i];
      EXPECT_TRUE(w.U == r.U && w.SxV == r.SxV && w.S == r.S) << "m " << m << ", matrix " << i;
      double e = 0;
      for (size_t t = 0; t < n; ++t)
        for (size_t k = 0; k < m; ++k) e += double(B(Eigen::Index(3 * k + i), Eigen::Index(t))) * B(Eigen::Index(3 * k + i), Eigen::Index(t));
      EXPECT_NEAR(r.total_energy, e, 1e-10 * e) << "m " << m << ", matrix " << i;
      EXPECT_NEAR(r.total_energy, w.total_energy, 1e-12 * e) << "m " << m << ", matrix " << i;
      EXPECT_GT(r.rel_error_estimate(), 0.0);
    }
    EXPECT_GT(got.value()[2].total_energy, 2 * got.value()[0].total_energy) << "the channels' energies differ: each is its own";
  }
}

TEST(StreamingDfmf, ChannelChunksAreTheInCoreTransform) {
  const Btf b = noisy(6, 5);
  const size_t rows = b.desc().num_images();
  MemorySource src(b, 7);
  for (int k = 0; k < 3; ++k) {
    DfmfChannelSource ch(src, k, 0.25f);
    ASSERT_EQ(ch.rows(), rows);
    std::vector<uint8_t> raw(ch.raw_buffer_bytes(1));
    std::vector<float> got(rows * ch.chunk_count(1)), want(got.size());
    ASSERT_TRUE(ch.load(1, raw.data(), got.data()).ok());
    size_t clamped = 0;
    for (size_t t = 0; t < ch.chunk_count(1); ++t) clamped += dfmf_channel(b.abrdf(7 + t), rows, k, 0.25f, &want[t * rows]);
    EXPECT_EQ(got, want) << "channel " << k;
    EXPECT_EQ(ch.clamped(), k == 0 ? clamped : 0u);
    // read() + decode() give the same values as load().
    std::vector<uint8_t> raw2(ch.raw_bytes(1));
    std::vector<float> again(got.size());
    ASSERT_TRUE(ch.read(1, raw2.data()).ok());
    ASSERT_TRUE(ch.decode(1, raw2.data(), again.data()).ok());
    EXPECT_EQ(again, want);
  }
}

TEST(StreamingExact, MatchesTheInCoreExactSvd) {
  const Btf b = synth(24, 24);  // 486 x 576: the rows side is the small one, as in core
  const size_t m = b.desc().abrdf_size(), n = b.desc().num_texels();
  SvdOptions opt;
  opt.max_rank = 12, opt.method = SvdMethod::exact;
  auto in_core = truncated_svd(b.data(), m, n, opt);
  ASSERT_TRUE(in_core.ok());
  MemorySource src(b, 70);
  Collective one;
  StreamStats st;
  auto streamed = fmf::streaming_exact_svd(src, owned_chunks(src, 0, 1), opt, one, &st);
  ASSERT_TRUE(streamed.ok()) << streamed.status().message();
  EXPECT_EQ(st.passes, 2);
  EXPECT_EQ(st.bytes_read, uint64_t(2) * m * n * 4);
  ASSERT_EQ(streamed->U.cols(), 12);
  const double e_in = actual_error(b, in_core.value()), e_st = actual_error(b, streamed.value());
  EXPECT_GT(e_in, 0.001);
  EXPECT_LT(std::fabs(e_st - e_in) / e_in, 1e-5) << "in core " << e_in << ", streamed " << e_st;
  EXPECT_LT(std::fabs(streamed->rel_error_estimate() - in_core->rel_error_estimate()) / e_in, 1e-5);
  EXPECT_LT((streamed->S - in_core->S).norm() / in_core->S.norm(), 1e-6);
  // The same subspace: the projectors U U^T agree (signs of components do not matter).
  const Eigen::MatrixXd Ui = in_core->U.cast<double>(), Us = streamed->U.cast<double>();
  EXPECT_LT((Ui * Ui.transpose() - Us * Us.transpose()).norm(), 1e-5);
  // Mapped chunks give the same factorization.
  src.mapped = true;
  auto mapped = fmf::streaming_exact_svd(src, owned_chunks(src, 0, 1), opt, one);
  ASSERT_TRUE(mapped.ok());
  EXPECT_LT((mapped->U - streamed->U).norm(), 1e-6);
}

TEST(StreamingExact, TargetErrorPicksTheInCoreRank) {
  const Btf b = synth(24, 24);
  SvdOptions opt;
  opt.max_rank = 40, opt.target_rel_error = 0.05, opt.method = SvdMethod::exact;
  auto in_core = truncated_svd(b.data(), b.desc().abrdf_size(), b.desc().num_texels(), opt);
  MemorySource src(b, 100);
  Collective one;
  auto streamed = fmf::streaming_exact_svd(src, owned_chunks(src, 0, 1), opt, one);
  ASSERT_TRUE(in_core.ok() && streamed.ok());
  EXPECT_GT(in_core->U.cols(), 1);
  EXPECT_LT(in_core->U.cols(), 40);
  EXPECT_EQ(streamed->U.cols(), in_core->U.cols());
  EXPECT_LE(streamed->rel_error_estimate(), 0.05);
  EXPECT_TRUE(streamed->target_reached);
}

TEST(StreamingExact, ThreeProcessesGiveTheOneProcessResultAndAgreeOnFailures) {
  const Btf b = synth(16, 15);
  MemorySource src(b, 32);  // 8 chunks over 3 processes
  SvdOptions opt;
  opt.max_rank = 8;
  Collective one;
  auto ref = fmf::streaming_exact_svd(src, owned_chunks(src, 0, 1), opt, one);
  ASSERT_TRUE(ref.ok());
  for (bool fail : {false, true}) {
    src.fail_chunk = fail ? 7 : size_t(-1);  // chunk 7 belongs to process 2
    std::vector<Result<SvdResult>> res(3, Result<SvdResult>(Status{}));
    run_group(3, [&](Collective& me, int r) { res[size_t(r)] = fmf::streaming_exact_svd(src, owned_chunks(src, r, 3), opt, me); });
    if (fail) {
      for (int r = 0; r < 3; ++r)
        EXPECT_NE(res[size_t(r)].status().message().find("rank 2: cannot read chunk 7"), std::string::npos) << res[size_t(r)].status().message();
      continue;
    }
    for (int r = 0; r < 3; ++r) ASSERT_TRUE(res[size_t(r)].ok()) << res[size_t(r)].status().message();
    EXPECT_TRUE(res[1]->SxV.size() == 0 && res[2]->SxV.size() == 0);
    Eigen::MatrixXd A = ref->U.cast<double>() * ref->SxV.cast<double>().transpose();
    Eigen::MatrixXd B = res[0]->U.cast<double>() * res[0]->SxV.cast<double>().transpose();
    EXPECT_GT(A.norm(), 0);
    EXPECT_LT((A - B).norm() / A.norm(), 1e-5);
  }
}

TEST(StreamingDfmf, ThreeProcessesGiveTheOneProcessModelRandomizedAndExact) {
  const Btf b = noisy(16, 15);
  MemorySource src(b, 24);  // 10 chunks
  for (const char* svd : {"randomized", "exact"}) {
    auto spec = resolve_spec(std::string("fmf:color=dfmf:rank=8:chroma_rank=4:oversample=6:power_iters=2:precision=float:svd=") + svd);
    ASSERT_TRUE(spec.ok());
    auto one = encode_on(1, src, b, spec->second), three = encode_on(3, src, b, spec->second);
    ASSERT_TRUE(one.ok()) << one.status().message();
    ASSERT_TRUE(three.ok()) << three.status().message();
    EXPECT_LT(model_difference(*one->model, *three->model), 1e-4) << svd;
    EXPECT_EQ(stat(*three->model, "negative_luminance_clamped"), stat(*one->model, "negative_luminance_clamped")) << svd;
    EXPECT_GT(stat(*three->model, "negative_luminance_clamped"), 0);
    // Exact: 2 passes per channel; randomized: the three in one stream of power_iters + 2 passes
    // at most (the error-driven stop may end it earlier; one and three processes alike).
    if (std::string(svd) == "exact") {
      EXPECT_EQ(stat(*three->model, "stream.passes"), 6);
    }
    else EXPECT_LE(stat(*three->model, "stream.passes"), 4);
    EXPECT_EQ(stat(*three->model, "stream.passes"), stat(*one->model, "stream.passes")) << svd;
  }
}

TEST(StreamingExact, StreamedDfmfExactMatchesInCore) {
  const Btf b = noisy(24, 24);  // 162 images x 576 texels
  auto spec = resolve_spec("fmf:color=dfmf:rank=10:chroma_rank=5:svd=exact:precision=float");
  Context ctx;
  auto in_core = spec->first->encode(b, spec->second, ctx);
  ASSERT_TRUE(in_core.ok());
  MemorySource src(b, 100);
  Collective one;
  auto st = encode_fmf_streamed(src, b.desc(), spec->second, ctx, one);
  ASSERT_TRUE(st.ok()) << st.status().message();
  const double e_in = model_error(b, *in_core.value()), e_st = model_error(b, *st->model);
  EXPECT_GT(e_in, 1e-3);
  EXPECT_LT(std::fabs(e_st - e_in) / e_in, 1e-4) << e_in << " " << e_st;
  EXPECT_LT(model_difference(*in_core.value(), *st->model), 1e-4);
}

// The randomized plan sums the sparse sketch over the chunks (an m x s float buffer, SvdOptions::
// sketch_sums) when memory allows, and not when the buffer would take half the chunks' lines.
TEST(StreamingFmf, PlanSumsTheSketchWhereMemoryAllows) {
  BtfDesc d;
  d.width = 56, d.height = 56, d.channels = 3, d.lights = DirectionSet::ubo2003(), d.views = DirectionSet::ubo2003();
  auto spec = resolve_spec("fmf:rank=32:svd=randomized:power_iters=0");  // one block at any limit: plans differ by the buffer only
  ASSERT_TRUE(spec.ok());
  auto roomy = plan_streamed_fmf(spec->second, d, size_t(1) << 30);
  ASSERT_TRUE(roomy.ok()) << roomy.status().message();
  EXPECT_TRUE(roomy->sketch_sums);
  const uint64_t sums = column_sketch_sums_bytes(d.abrdf_size(), d.num_texels(), Eigen::Index(roomy->l));
  EXPECT_EQ(sums, d.abrdf_size() * 256 * 4);  // l = 48: s = 256
  // 40 MiB: the buffer (19.2 MiB) would not fit beside the rest; the plan streams without it.
  auto tight = plan_streamed_fmf(spec->second, d, size_t(40) << 20);
  ASSERT_TRUE(tight.ok()) << tight.status().message();
  EXPECT_FALSE(tight->sketch_sums);
  ASSERT_EQ(roomy->kept_blocks, tight->kept_blocks);
  EXPECT_EQ(roomy->fixed_bytes - tight->fixed_bytes, sums);  // counted in the plan's memory
}

TEST(StreamingExact, GramThatDoesNotFitIsRefusedNamingTheSizes) {
  const Btf b = synth(8, 8);  // 486 rows
  auto exact = resolve_spec("fmf:rank=8:svd=exact"), automatic = resolve_spec("fmf:rank=8");
  ASSERT_TRUE(exact.ok() && automatic.ok());
  // With room: both resolve to the exact path.
  auto roomy = plan_streamed_fmf(exact->second, b.desc(), size_t(1) << 30);
  ASSERT_TRUE(roomy.ok());
  EXPECT_TRUE(roomy->exact);
  EXPECT_EQ(roomy->passes, 2);
  EXPECT_TRUE(plan_streamed_fmf(automatic->second, b.desc(), size_t(1) << 30)->exact);
  // 486^2 doubles = 1.8 MiB, x 3 with the solver + the 16 MiB allowance: does not fit 4 MiB.
  auto tight = plan_streamed_fmf(exact->second, b.desc(), size_t(4) << 20);
  ASSERT_FALSE(tight.ok());
  EXPECT_EQ(tight.status().code(), StatusCode::invalid_argument);
  EXPECT_NE(tight.status().message().find("486 x 486 Gram matrix"), std::string::npos) << tight.status().message();
  EXPECT_NE(tight.status().message().find("--max-memory 4.0 MiB"), std::string::npos) << tight.status().message();
  // svd=auto falls back to the randomized path and says so.
  auto fallback = plan_streamed_fmf(automatic->second, b.desc(), size_t(4) << 20);
  ASSERT_TRUE(fallback.ok());
  EXPECT_FALSE(fallback->exact);
  EXPECT_NE(fallback->note.find("does not fit"), std::string::npos) << fallback->note;
  // The encode refuses the same way (its limit is the context's).
  MemorySource src(b, 16);
  Context ctx;
  ctx.max_bytes = size_t(4) << 20;
  Collective one;
  EXPECT_EQ(encode_fmf_streamed(src, b.desc(), exact->second, ctx, one).status().code(), StatusCode::invalid_argument);
}
