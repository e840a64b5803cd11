// Helpers the codec tests share: encoding by spec string, the --max-bytes search check.
#pragma once
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>
#include <cstdint>
#include <memory>
#include <string>

#include "codecs/codec.h"
#include "codecs/target.h"
#include "core/metrics.h"

namespace btfc::test {

// Random queries: theta up to 95 degrees (beyond every hull, a few below the horizon), some
// measured, some runs of one direction pair (frames), texels anywhere.
inline std::vector<EvalQuery> random_eval_queries(const BtfDesc& d, size_t n, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<EvalQuery> q(n);
  for (size_t i = 0; i < n; ++i) {
    EvalQuery& e = q[i];
    e.x = int(rng() % unsigned(d.width)), e.y = int(rng() % unsigned(d.height));
    const unsigned kind = rng() % 8;
    if (kind == 0) {
      e.light = int(rng() % d.num_lights()), e.view = int(rng() % d.num_views());
    } else if (kind == 1 && i > 0 && q[i - 1].light < 0) {
      e.wl = q[i - 1].wl, e.wv = q[i - 1].wv;  // same pair as the previous query
    } else if (kind == 2) {
      e.wl = d.lights.dirs[rng() % d.num_lights()], e.wv = d.views.dirs[rng() % d.num_views()];  // exactly measured
    } else {
      e.wl = dir_from_theta_phi(u(rng) * 95 * M_PI / 180, u(rng) * 2 * M_PI);
      e.wv = dir_from_theta_phi(u(rng) * 95 * M_PI / 180, u(rng) * 2 * M_PI);
    }
  }
  return q;
}

// eval_batch of `m` against eval / eval_dir per query on random_eval_queries(n, seed): the
// largest difference relative to max(1, |reference|). Then one query outside the BTF: eval_batch
// must fail naming it and write nothing.
inline double eval_batch_vs_eval_dir(const Model& m, size_t n, unsigned seed) {
  const BtfDesc& d = m.desc();
  std::vector<EvalQuery> q = random_eval_queries(d, n, seed);
  const size_t nc = size_t(d.channels);
  std::vector<float> got(nc * n), ref(nc);
  const Status st = m.eval_batch(q, got.data());
  EXPECT_TRUE(st.ok()) << st.message();
  double worst = 0;
  for (size_t i = 0; i < n; ++i) {
    if (q[i].light >= 0) m.eval(q[i].x, q[i].y, q[i].light, q[i].view, ref.data());
    else EXPECT_TRUE(m.eval_dir(q[i].x, q[i].y, q[i].wl, q[i].wv, ref.data()).ok());
    for (size_t c = 0; c < nc; ++c) worst = std::max(worst, std::abs(double(got[nc * i + c]) - ref[c]) / std::max(1.0, std::abs(double(ref[c]))));
  }
  q[n / 2].y = d.height;
  std::fill(got.begin(), got.end(), -7.f);
  const Status bad = m.eval_batch(q, got.data());
  EXPECT_FALSE(bad.ok());
  EXPECT_NE(bad.message().find("outside the BTF"), std::string::npos) << bad.message();
  EXPECT_EQ(std::count(got.begin(), got.end(), -7.f), std::ptrdiff_t(got.size()));
  return worst;
}

// Encodes `b` with the registry's codec for `spec` ("fmf:rank=8", parameters as the CLI takes
// them) and Context::seed = `seed` (the default Context's). An unknown spec or a failed encode
// fails the test and returns nullptr.
inline std::unique_ptr<Model> encode_spec(const Btf& b, const std::string& spec, uint64_t seed = 1) {
  auto r = resolve_spec(spec);
  EXPECT_TRUE(r.ok()) << spec << ": " << r.status().message();
  if (!r.ok()) return nullptr;
  Context ctx;
  ctx.seed = seed;
  auto m = r->first->encode(b, r->second, ctx);
  EXPECT_TRUE(m.ok()) << spec << ": " << m.status().message();
  return m.ok() ? std::move(m).value() : nullptr;
}

// --max-bytes over a codec's settings (its budget_variants: half and precision=q at bits 4, 6, 8):
// the search from `spec` fits `budget` (the .btfc file's bytes) and chose a precision=q setting; the search from
// `half_spec` (the precision fixed to half) fits too and keeps half; the full search is at least as
// good as the half-only one.
inline void expect_budget_search_beats_half(const Btf& b, const std::string& spec, const std::string& half_spec, double budget) {
  Context ctx;
  auto any = choose_for_target(b, spec, Target{Target::Kind::max_bytes, budget}, ctx);
  ASSERT_TRUE(any.ok()) << spec << ": " << any.status().message();
  EXPECT_LE(any->measure, budget);  // the .btfc file's bytes (model_file_bytes)
  EXPECT_EQ(any->measure, double(model_file_bytes(*any->model, *resolve_spec(any->spec).value().first).value()));
  EXPECT_NE(any->variants.find("precision=q"), std::string::npos) << any->variants;
  auto half = choose_for_target(b, half_spec, Target{Target::Kind::max_bytes, budget}, ctx);
  ASSERT_TRUE(half.ok()) << half_spec << ": " << half.status().message();
  EXPECT_LE(half->measure, budget);
  EXPECT_NE(half->model->spec().find("precision=half"), std::string::npos) << half->model->spec();
  Btf out;
  ASSERT_TRUE(half->model->decode_all(out).ok());
  EXPECT_GE(any->psnr, compare_btf(b, out, false).value().psnr) << any->variants;
}

}  // namespace btfc::test
