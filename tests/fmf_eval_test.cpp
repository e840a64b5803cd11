// The fmf random-access path (codecs/fmf/fmf_eval.h) against its reference: Model::eval_batch's
// per-query eval / eval_dir. Every kernel shape (rgb and grey, ranks that take the register
// kernels and ranks that take the generic loop), random directions inside and outside the
// measured hull, measured queries, a renderer's frames, and batches spanning several blocks.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "codecs/codec.h"
#include "codecs/fmf/fmf_eval.h"
#include "core/cl_runtime.h"
#include "core/interp.h"
#include "tests/codec_test_util.h"

using namespace btfc;

namespace {

using test::encode_spec;
using test::random_eval_queries;

Btf random_btf(const BtfDesc& d, unsigned seed) {
  Btf b = Btf::create(d).value();
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0, 1);
  for (size_t i = 0; i < b.size(); ++i) b.data()[i] = u(rng) * u(rng) * 4.0f;  // full rank, HDR-ish
  return b;
}

BtfDesc desc(int w, int h, int channels, const DirectionSet& lights, const DirectionSet& views) {
  BtfDesc d;
  d.width = w, d.height = h, d.channels = channels, d.lights = lights, d.views = views;
  return d;
}

DirectionSet first(const DirectionSet& s, size_t n) {
  DirectionSet out = s;
  out.dirs.resize(n);
  out.name = "custom";
  return out;
}

// max |a - b| / max |b|
double rel_max_diff(const std::vector<float>& a, const std::vector<float>& b) {
  double num = 0, den = 0;
  for (size_t i = 0; i < a.size(); ++i) num = std::max(num, double(std::fabs(a[i] - b[i]))), den = std::max(den, double(std::fabs(b[i])));
  return num / den;
}

void expect_fast_equals_reference(const Model& m, const std::vector<EvalQuery>& q, const std::string& what) {
  const size_t nc = size_t(m.desc().channels);
  std::vector<float> fast(q.size() * nc, -1.0f), ref(q.size() * nc, -2.0f);
  ocl::set_device_choice(ocl::DeviceChoice::cpu);
  ASSERT_TRUE(m.eval_batch(q, fast.data()).ok()) << what;
  ocl::set_device_choice(ocl::DeviceChoice::automatic);
  ASSERT_TRUE(m.Model::eval_batch(q, ref.data()).ok()) << what;
  const double d = rel_max_diff(fast, ref);
  EXPECT_LE(d, 1e-5) << what;
  // The blend order differs from the reference's, so the two are not bit-equal in general: a
  // path that returned the reference itself would hide a broken fast path from this test.
  EXPECT_GT(d, 0.0) << what << ": bit-equal to the reference, is the fast path running?";
}

// Queries at measured (light, view) indices of a 5 x 4-texel BTF with 20 lights and 9 views; the
// CPU path's eval_batch equals eval() there to `tol` relative. Returns the queries.
std::vector<EvalQuery> expect_measured_equals_eval(const Model& m, float tol) {
  std::vector<EvalQuery> q;
  for (int l = 0; l < 20; l += 3)
    for (int v = 0; v < 9; v += 2) {
      EvalQuery e;
      e.x = l % 5, e.y = v % 4, e.light = l, e.view = v;
      q.push_back(e);
    }
  std::vector<float> got(3 * q.size());
  ocl::set_device_choice(ocl::DeviceChoice::cpu);
  EXPECT_TRUE(m.eval_batch(q, got.data()).ok());
  ocl::set_device_choice(ocl::DeviceChoice::automatic);
  for (size_t i = 0; i < q.size(); ++i) {
    float e[3];
    m.eval(q[i].x, q[i].y, q[i].light, q[i].view, e);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(got[3 * i + c], e[c], tol * (1 + std::fabs(e[c]))) << i;
  }
  return q;
}

}  // namespace

TEST(FmfEval, EveryKernelShapeMatchesTheReference) {
  // ranks 16, 32, 48 take the register kernels (C a multiple of 16), 5 and 20 the generic loop.
  // precision=half (the default) stores U as halves, which an AVX-512 CPU blends unsorted from a
  // half copy (blend_half_avx512); precision=float takes the sorted float kernels.
  const DirectionSet L = first(DirectionSet::ubo2003(), 31), V = first(DirectionSet::ubo2003(), 13);
  for (const char* precision : {"half", "float"})
    for (int channels : {3, 1})
      for (int rank : {5, 16, 20, 32, 48}) {
        const BtfDesc d = desc(13, 11, channels, L, V);
        auto m = encode_spec(random_btf(d, unsigned(rank + channels)), "fmf:rank=" + std::to_string(rank) + ":precision=" + precision);
        ASSERT_TRUE(m);
        expect_fast_equals_reference(*m, random_eval_queries(d, 3000, unsigned(rank)),
                                     std::string(precision) + " channels " + std::to_string(channels) + " rank " + std::to_string(rank));
      }
}

TEST(FmfEval, EveryBlendKernelThisCpuRunsMatchesTheReference) {
  // The AVX2 kernel (CPUs without AVX-512 take it) and the generic loop, forced, on the shapes
  // the register kernels take; the test above runs the best kernel of whatever CPU runs it.
  const DirectionSet L = first(DirectionSet::ubo2003(), 31), V = first(DirectionSet::ubo2003(), 13);
  int ran = 0;
  for (fmf::EvalPath path : {fmf::EvalPath::avx2, fmf::EvalPath::generic}) {
    if (!fmf::set_eval_path(path)) continue;
    ++ran;
    for (int channels : {3, 1})
      for (int rank : {8, 16, 32, 48}) {
        const BtfDesc d = desc(9, 7, channels, L, V);
        auto m = encode_spec(random_btf(d, unsigned(rank * channels)), "fmf:rank=" + std::to_string(rank));
        ASSERT_TRUE(m);
        expect_fast_equals_reference(*m, random_eval_queries(d, 2000, unsigned(rank + 7)),
                                     "path " + std::to_string(int(path)) + " channels " + std::to_string(channels) + " rank " + std::to_string(rank));
      }
  }
  ASSERT_TRUE(fmf::set_eval_path(fmf::EvalPath::best));
  EXPECT_GE(ran, 1);  // the generic loop runs everywhere
}

TEST(FmfEval, BatchesOverSeveralBlocksAndFullDirectionSets) {
  // More queries than fmf::k_eval_block (several sorted blocks, both threads), the 81 x 81 set.
  const BtfDesc d = desc(16, 16, 3, DirectionSet::ubo2003(), DirectionSet::ubo2003());
  auto m = encode_spec(random_btf(d, 3), "fmf:rank=32");
  ASSERT_TRUE(m);
  expect_fast_equals_reference(*m, random_eval_queries(d, 3 * fmf::k_eval_block + 123, 9), "81 x 81, rank 32");
  // A renderer's frames: every texel under one pair, three pairs.
  std::vector<EvalQuery> frames;
  for (int f = 0; f < 3; ++f)
    for (int y = 0; y < 16; ++y)
      for (int x = 0; x < 16; ++x) {
        EvalQuery e;
        e.x = x, e.y = y, e.wl = dir_from_theta_phi(0.3 * f, 1.0 + f), e.wv = dir_from_theta_phi(0.2 + 0.1 * f, 2.0);
        frames.push_back(e);
      }
  expect_fast_equals_reference(*m, frames, "frames");
}

TEST(FmfEval, ExactAtMeasuredDirectionsAndBadQueriesAreErrors) {
  const BtfDesc d = desc(5, 4, 3, first(DirectionSet::ubo2003(), 20), first(DirectionSet::ubo2003(), 9));
  auto m = encode_spec(random_btf(d, 5), "fmf:rank=16");
  ASSERT_TRUE(m);
  // At measured (light, view) indices a single row is read: equal to eval() to rounding.
  std::vector<EvalQuery> q = expect_measured_equals_eval(*m, 1e-6f);
  // A query outside the BTF is an error naming it, as on the reference path.
  q.back().x = 5;
  std::vector<float> got(3 * q.size());
  ocl::set_device_choice(ocl::DeviceChoice::cpu);
  const Status s = m->eval_batch(q, got.data());
  ocl::set_device_choice(ocl::DeviceChoice::automatic);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("outside the BTF"), std::string::npos) << s.message();
}

TEST(FmfEval, DfmfPathMatchesTheReference) {
  // color=dfmf (fmf_eval_dfmf.cpp): ranks below, at and above a multiple of 8 (the dots' vector
  // width), a chroma rank other than the luminance's, the automatic and Bonn's offsets, one
  // channel set spanning 1e-6..1e6 (log Y from -14 to 14), several blocks of queries.
  const DirectionSet L = first(DirectionSet::ubo2003(), 31), V = first(DirectionSet::ubo2003(), 13);
  const BtfDesc d = desc(11, 9, 3, L, V);
  Btf hdr = random_btf(d, 17);
  std::mt19937 rng(4);
  for (size_t i = 0; i < hdr.size(); ++i) hdr.data()[i] = float(std::pow(10.0, -6.0 + 12.0 * double(rng() % 1000) / 999.0));
  struct Case {
    const Btf* b;
    std::string spec;
  };
  const Btf ldr = random_btf(d, 18);
  for (const Case& c : {Case{&ldr, "fmf:color=dfmf:rank=5"}, Case{&ldr, "fmf:color=dfmf:rank=16:chroma_rank=9"},
                        Case{&ldr, "fmf:color=dfmf:rank=20:offset=1e-5"}, Case{&hdr, "fmf:color=dfmf:rank=12"}}) {
    auto m = encode_spec(*c.b, c.spec);
    ASSERT_TRUE(m) << c.spec;
    expect_fast_equals_reference(*m, random_eval_queries(d, 9000, 3), c.spec);
  }
}

TEST(FmfEval, DfmfPathAtMeasuredDirectionsEqualsEval) {
  const BtfDesc d = desc(5, 4, 3, first(DirectionSet::ubo2003(), 20), first(DirectionSet::ubo2003(), 9));
  auto m = encode_spec(random_btf(d, 6), "fmf:color=dfmf:rank=8");
  ASSERT_TRUE(m);
  expect_measured_equals_eval(*m, 1e-5f);  // exp_poly and the dots' order: rounding apart
}
