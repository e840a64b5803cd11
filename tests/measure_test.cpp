// Tests of the measuring side: sweep expansion, Pareto fronts, benchmark determinism, budget
// targeting (codecs/target.h) and the CPU renderer (codecs/render.h).
#include <gtest/gtest.h>

#include <cstring>

#include <cmath>

#include "codecs/fmf/fmf.h"
#include "codecs/lpca/lpca.h"
#include "codecs/measure.h"
#include "codecs/target.h"
#include "core/svd.h"
#include "core/synth.h"

using namespace btfc;

namespace {

constexpr double k_pi = 3.14159265358979323846;

Btf small_btf(int w = 12, int h = 12) {
  SynthOptions o;
  o.width = w, o.height = h;
  auto b = synthesize_btf(o);
  EXPECT_TRUE(b.ok()) << b.status().message();
  return std::move(b).value();
}

Btf constant_btf(float value, int w = 8, int h = 6) {
  BtfDesc d;
  d.width = w, d.height = h;
  d.lights = DirectionSet::ubo2003(), d.views = DirectionSet::ubo2003();
  auto b = Btf::create(d);
  EXPECT_TRUE(b.ok());
  std::fill(b->data(), b->data() + b->size(), value);
  return std::move(b).value();
}

Metrics measure(const Btf& ref, const std::string& spec) {
  auto r = resolve_spec(spec);
  EXPECT_TRUE(r.ok()) << r.status().message();
  Context ctx;
  auto m = r->first->encode(ref, r->second, ctx);
  EXPECT_TRUE(m.ok()) << m.status().message();
  Btf out;
  EXPECT_TRUE(m.value()->decode_all(out).ok());
  return compare_btf(ref, out, false).value();
}

uint64_t bytes_of(const Btf& ref, const std::string& spec) {
  auto r = resolve_spec(spec);
  Context ctx;
  return model_file_bytes(*r->first->encode(ref, r->second, ctx).value(), *r->first).value();
}

}  // namespace

TEST(Sweep, ExpandsCommaListsInOrder) {
  auto s = expand_sweep("fmf:rank=4,8:precision=half,float");
  ASSERT_TRUE(s.ok()) << s.status().message();
  EXPECT_EQ(*s, (std::vector<std::string>{"fmf:rank=4:precision=half", "fmf:rank=4:precision=float",
                                          "fmf:rank=8:precision=half", "fmf:rank=8:precision=float"}));
  EXPECT_EQ(expand_sweep("lpyr").value(), std::vector<std::string>{"lpyr"});
  EXPECT_FALSE(expand_sweep("fmf:rank=4,,8").ok());
  EXPECT_FALSE(expand_sweep("fmf:rank").ok());
}

TEST(Pareto, KeepsOnlyRunsThatBeatEveryCheaperOne) {
  std::vector<BenchResult> r(4);
  const uint64_t bytes[4] = {100, 200, 150, 300};
  const double psnr[4] = {20, 25, 26, 24};
  std::vector<const BenchResult*> p;
  for (int i = 0; i < 4; ++i) r[size_t(i)].payload_bytes = bytes[i], r[size_t(i)].metrics.psnr = psnr[i], p.push_back(&r[size_t(i)]);
  const auto front = pareto_front(p, [](const BenchResult& b) { return b.metrics.psnr; });
  EXPECT_EQ(front, (std::vector<size_t>{0, 2}));  // 200 B at 25 dB loses to 150 B at 26 dB; 300 B at 24 dB too
}

TEST(Bench, SameSpecSameDataGivesSameBytesAndMetrics) {
  const Btf b = small_btf();
  BenchOptions opt;
  opt.throughput_queries = 1000, opt.throughput_seconds = 0;
  for (const char* spec : {"fmf:rank=4", "lpca:clusters=3:components=2", "lpyr"}) {
    auto r1 = run_benchmark(b, spec, opt), r2 = run_benchmark(b, spec, opt);
    ASSERT_TRUE(r1.ok() && r2.ok()) << spec;
    EXPECT_EQ(r1->tensor_digest, r2->tensor_digest) << spec;
    EXPECT_NE(r1->tensor_digest, 0u);
    EXPECT_EQ(r1->payload_bytes, r2->payload_bytes);
    EXPECT_EQ(r1->metrics.rmse, r2->metrics.rmse);
    EXPECT_EQ(r1->metrics.mean_ssim, r2->metrics.mean_ssim);
    EXPECT_EQ(r1->render_ssim, r2->render_ssim);
    EXPECT_GT(r1->render_ssim, 0.3);
    EXPECT_LE(r1->render_ssim, 1.0);
    EXPECT_GT(r1->evals_per_second, 0);
    EXPECT_GT(r1->peak_rss_bytes, 0u);
  }
  auto a = run_benchmark(b, "fmf:rank=4", opt), c = run_benchmark(b, "fmf:rank=5", opt);
  EXPECT_NE(a->tensor_digest, c->tensor_digest);
  // More rank: more bytes, lower error (the ratio columns mean what they say).
  EXPECT_GT(c->payload_bytes, a->payload_bytes);
  EXPECT_LT(c->metrics.rmse, a->metrics.rmse);
  EXPECT_NEAR(a->ratio, double(b.desc().num_values()) * 4 / double(a->payload_bytes), 1e-9);
}

TEST(Target, PsnrChoosesTheCheapestRankThatMeetsIt) {
  const Btf b = small_btf();
  const double p4 = measure(b, "fmf:rank=4:svd=exact").psnr, p9 = measure(b, "fmf:rank=9:svd=exact").psnr;
  ASSERT_LT(p4, p9);
  Target t{Target::Kind::psnr, 0.5 * (p4 + p9)};
  Context ctx;
  auto c = choose_for_target(b, "fmf:svd=exact", t, ctx);
  ASSERT_TRUE(c.ok()) << c.status().message();
  EXPECT_EQ(c->knob, "rank");
  const int k = int(c->knob_value);
  EXPECT_GT(k, 4);
  EXPECT_LE(k, 9);
  EXPECT_GE(c->measure, t.value);
  EXPECT_GE(measure(b, "fmf:svd=exact:rank=" + std::to_string(k)).psnr, t.value);
  EXPECT_LT(measure(b, "fmf:svd=exact:rank=" + std::to_string(k - 1)).psnr, t.value);  // next cheaper misses
  EXPECT_EQ(c->spec, c->model->spec());
}

TEST(Target, SsimOnLpcaComponents) {
  const Btf b = small_btf();
  Context ctx;
  auto c = choose_for_target(b, "lpca:clusters=2:components=2", Target{Target::Kind::ssim, 0.9}, ctx);
  ASSERT_TRUE(c.ok()) << c.status().message();
  EXPECT_EQ(c->knob, "components");
  EXPECT_GE(c->measure, 0.9);
  const int k = int(c->knob_value);
  if (k > 1) {
    auto r = resolve_spec("lpca:clusters=2:components=" + std::to_string(k - 1));
    auto m = r->first->encode(b, r->second, ctx);
    Btf out;
    ASSERT_TRUE(m.value()->decode_all(out).ok());
    EXPECT_LT(compare_btf(b, out, true)->mean_ssim, 0.9);
  }
}

TEST(Target, ByteBudgetChoosesTheLargestThatFits) {
  const Btf b = small_btf();
  const uint64_t b6 = bytes_of(b, "fmf:rank=6"), b7 = bytes_of(b, "fmf:rank=7");
  Context ctx;
  // precision fixed by the spec: only the rank is searched (plain "fmf" also tries precision=q).
  auto c = choose_for_target(b, "fmf:precision=half", Target{Target::Kind::max_bytes, double(b6 + (b7 - b6) / 2)}, ctx);
  ASSERT_TRUE(c.ok()) << c.status().message();
  EXPECT_EQ(int(c->knob_value), 6);
  // The budget counts the .btfc file (payload, headers, directions, statistics), not the payload.
  EXPECT_EQ(c->measure, double(model_file_bytes(*c->model, fmf_codec()).value()));
  EXPECT_LE(c->measure, double(b6 + (b7 - b6) / 2));
  EXPECT_LT(c->model->payload_bytes() + 1000, uint64_t(c->measure));
  // Half-float bytes are linear in the rank: from the default (32) the estimate lands on 6 and its
  // neighbour 7 closes the bracket; bisection over 1..32 would take 5 or more encodes.
  EXPECT_LE(c->probes.size(), 3u);
}

TEST(Target, ByteBudgetProbesNoKnobAboveTheCodecsLimit) {
  const Btf b = small_btf(24, 24);  // 576 texels: lpca's budget limit is 576 / 64 = 9 components
  const Codec* lpca = find_codec("lpca");
  ASSERT_NE(lpca, nullptr);
  ASSERT_EQ(lpca->budget_knob_limit(b.desc()), 9);
  Context ctx;
  const Target all{Target::Kind::max_bytes, 1e12};  // a budget no setting fills
  auto c = choose_for_target(b, "lpca:clusters=1:precision=half:components=2", all, ctx);
  ASSERT_TRUE(c.ok()) << c.status().message();
  EXPECT_EQ(int(c->knob_value), 9);
  EXPECT_EQ(c->knob_limit, 9);
  for (const TargetProbe& p : c->probes) EXPECT_LE(p.knob, 9);
  // The spec's own value is always allowed.
  auto own = choose_for_target(b, "lpca:clusters=1:precision=half:components=12", all, ctx);
  ASSERT_TRUE(own.ok()) << own.status().message();
  EXPECT_EQ(int(own->knob_value), 12);
}

// The search's chosen model decoded into x, and its spec encoded alone decoded into y.
void decode_chosen_and_alone(const Btf& b, const TargetChoice& c, Context& ctx, Btf& x, Btf& y) {
  auto again = resolve_spec(c.spec);
  ASSERT_TRUE(again.ok());
  auto m = again->first->encode(b, again->second, ctx);
  ASSERT_TRUE(m.ok());
  ASSERT_TRUE(c.model->decode_all(x).ok());
  ASSERT_TRUE(m.value()->decode_all(y).ok());
}

// A model chosen by a search whose probes shared factorizations (RandomizedSvdReuse) is as close
// to the data as its spec encoded alone (within 0.2 %) or closer.
void expect_searched_as_accurate_as_alone(const Btf& b, const TargetChoice& c, Context& ctx) {
  Btf x, y;
  ASSERT_NO_FATAL_FAILURE(decode_chosen_and_alone(b, c, ctx, x, y));
  auto ex = compare_btf(b, x, false), ey = compare_btf(b, y, false);
  ASSERT_TRUE(ex.ok() && ey.ok());
  std::printf("searched model %.6f, alone %.6f relative L2\n", ex->rel_l2, ey->rel_l2);
  EXPECT_LE(ex->rel_l2, 1.002 * ey->rel_l2);
}

TEST(Target, FmfByteBudgetLimitIsAQuarterOfTheSmallSideUpTo1024) {
  // fmf's budget limit: a quarter of the matrix's small side, at most 1024 where the SVD is
  // randomized (small side > 4096), and at least one rank per 64 texels.
  auto desc = [](int w, int h) {
    BtfDesc d;
    d.width = w, d.height = h;
    d.lights = d.views = DirectionSet::ubo2003();
    return d;
  };
  EXPECT_EQ(fmf_codec().budget_knob_limit(desc(40, 40)), 1600 / 4);    // exact: small side 1600
  EXPECT_EQ(fmf_codec().budget_knob_limit(desc(64, 64)), 4096 / 4);    // exact: small side 4096
  EXPECT_EQ(fmf_codec().budget_knob_limit(desc(80, 80)), 1024);        // randomized: 6400 / 4 capped
  EXPECT_EQ(fmf_codec().budget_knob_limit(desc(128, 128)), 1024);      // was 256 (16384 / 64)
  EXPECT_EQ(fmf_codec().budget_knob_limit(desc(512, 512)), 512 * 512 / 64);  // texels / 64 above
}

TEST(Target, FmfByteBudgetProbesShareRandomizedFactorizations) {
  // 40 x 40 texels (small side 1600): randomized below rank 184, where the probes take the
  // leading components of a few factorizations of growing rank (RandomizedSvdReuse) instead of
  // one each. The chosen model fits and is at least as accurate as its spec encoded alone.
  const Btf b = small_btf(40, 40);
  Context ctx;
  const size_t computed0 = RandomizedSvdReuse::computed(), served0 = RandomizedSvdReuse::served();
  const double budget = 1.5e5;  // about rank 120 with 8-bit factors
  auto c = choose_for_target(b, "fmf:precision=q:bits=8", Target{Target::Kind::max_bytes, budget}, ctx);
  ASSERT_TRUE(c.ok()) << c.status().message();
  const size_t computed = RandomizedSvdReuse::computed() - computed0, served = RandomizedSvdReuse::served() - served0;
  std::printf("chose %s (%.0f bytes, %.2f dB) after %zu probes: %zu randomized SVDs served %zu of them\n", c->spec.c_str(), c->measure,
              c->psnr, c->probes.size(), computed, served);
  EXPECT_LE(c->model->payload_bytes(), budget);
  bool randomized = false;
  for (const auto& [k, v] : c->model->stats().notes) randomized |= k == "svd.rgb" && v == "randomized";
  EXPECT_TRUE(randomized) << "the chosen rank is below the exact path's";
  EXPECT_GE(served, 4u);
  EXPECT_LE(2 * computed, served) << "at least two probes per factorization";
  expect_searched_as_accurate_as_alone(b, *c, ctx);
}

TEST(Target, DfmfByteBudgetProbesShareStreamedFactorizations) {
  // color=dfmf factorizes its three channel matrices in one stream (dfmf_streaming_svds), not
  // through truncated_svd: in a byte-budget search its probes take the leading components of a
  // few such streams of growing rank (RandomizedSvdReuse::serve_set, core/svd.h) instead of one
  // stream each. 40 x 40 texels: randomized below rank 184. The chosen model fits and is at
  // least as accurate as its spec encoded alone.
  const Btf b = small_btf(40, 40);
  Context ctx;
  const size_t computed0 = RandomizedSvdReuse::computed(), served0 = RandomizedSvdReuse::served();
  const double budget = 4e5;  // about rank 20 per channel with 8-bit factors
  auto c = choose_for_target(b, "fmf:color=dfmf:precision=q:bits=8", Target{Target::Kind::max_bytes, budget}, ctx);
  ASSERT_TRUE(c.ok()) << c.status().message();
  const size_t computed = RandomizedSvdReuse::computed() - computed0, served = RandomizedSvdReuse::served() - served0;
  std::printf("chose %s (%.0f bytes, %.2f dB) after %zu probes: %zu streams served %zu of them\n", c->spec.c_str(), c->measure, c->psnr,
              c->probes.size(), computed, served);
  EXPECT_LE(c->measure, budget);
  EXPECT_GE(c->knob_value, 16);
  std::string svd_y;
  for (const auto& [k, v] : c->model->stats().notes)
    if (k == "svd.y") svd_y = v;
  EXPECT_EQ(svd_y.rfind("randomized", 0), 0u) << svd_y;
  EXPECT_EQ(served, c->probes.size()) << "every probe through the kept streams";
  EXPECT_GE(served, 3u);
  EXPECT_LE(2 * computed, served) << "at least two probes per stream";
  expect_searched_as_accurate_as_alone(b, *c, ctx);
  // Outside a search nothing is kept or served.
  const size_t served1 = RandomizedSvdReuse::served();
  auto again = resolve_spec(c->spec);
  ASSERT_TRUE(again.ok());
  ASSERT_TRUE(again->first->encode(b, again->second, ctx).ok());
  EXPECT_EQ(RandomizedSvdReuse::served(), served1);
}

TEST(Target, FmfByteBudgetReachesAnyRankWhereTheExactSvdServesAll) {
  // A matrix whose small side is <= 4096 is factorized exactly at one cost for every rank
  // (core/svd.h), so fmf's budget limit is a quarter of that side, and the search computes the
  // decomposition once (ExactSvdReuse) for all its probes and settings.
  const Btf b = small_btf(24, 24);
  const long long side = (long long)std::min(b.desc().abrdf_size(), b.desc().num_texels());
  EXPECT_EQ(fmf_codec().budget_knob_limit(b.desc()), side / 4);
  Context ctx;
  const size_t before = ExactSvdReuse::reuses();
  const double budget = 400000;  // bytes: well above rank 9 (the old limit) at half precision
  auto c = choose_for_target(b, "fmf", Target{Target::Kind::max_bytes, budget}, ctx);
  ASSERT_TRUE(c.ok()) << c.status().message();
  const size_t reuses = ExactSvdReuse::reuses() - before;
  std::printf("chose %s (%.0f bytes, %.2f dB) after %zu probes, %zu exact SVDs reused\n", c->spec.c_str(), c->measure, c->psnr,
              c->probes.size(), reuses);
  EXPECT_LE(c->model->payload_bytes(), budget);
  EXPECT_GT(c->knob_value, 9);
  EXPECT_EQ(reuses + 1, c->probes.size());  // one decomposition for every probe
  // The chosen model is what a plain encode of its spec gives.
  Btf x, y;
  ASSERT_NO_FATAL_FAILURE(decode_chosen_and_alone(b, *c, ctx, x, y));
  EXPECT_EQ(0, std::memcmp(x.data(), y.data(), x.size() * sizeof(float)));
}

TEST(Target, CodecsThatCannotBeSearchedSaySoForAByteBudget) {
  const Btf b = small_btf(8, 8);
  Context ctx;
  auto c = choose_for_target(b, "mlvq", Target{Target::Kind::max_bytes, 1e6}, ctx);
  ASSERT_FALSE(c.ok());
  EXPECT_EQ(c.status().code(), StatusCode::unsupported);
  EXPECT_NE(c.status().message().find("--max-bytes is not supported"), std::string::npos) << c.status().message();
  EXPECT_NE(c.status().message().find("min_ratio"), std::string::npos) << c.status().message();
}

// mlvq's knob (ssim1) is one level's threshold of four: a PSNR above what it reaches with the
// other levels at their defaults is searched again through the codec's quality_variants.
TEST(Target, QualityTargetsEscalateThroughTheCodecsSettings) {
  const Btf b = small_btf(6, 6);
  Context ctx;
  const Target t{Target::Kind::psnr, 35};
  // noise fixed by the spec: the escalation settings (noise=off) do not apply, the knob alone misses.
  auto knob_only = choose_for_target(b, "mlvq:noise=auto", t, ctx);
  ASSERT_FALSE(knob_only.ok());
  EXPECT_NE(knob_only.status().message().find("out of reach"), std::string::npos) << knob_only.status().message();
  auto c = choose_for_target(b, "mlvq", t, ctx);
  ASSERT_TRUE(c.ok()) << c.status().message();
  EXPECT_GE(c->measure, 35);
  EXPECT_NE(c->variants.find("reached with ssim2=0.99"), std::string::npos) << c->variants;
  EXPECT_EQ(c->spec, c->model->spec());
  Btf out;
  ASSERT_TRUE(c->model->decode_all(out).ok());
  EXPECT_GE(compare_btf(b, out, false)->psnr, 35);
}

TEST(Target, UnreachableTargetsAreErrors) {
  const Btf b = small_btf(6, 6);
  Context ctx;
  auto hi = choose_for_target(b, "fmf:precision=half", Target{Target::Kind::psnr, 400}, ctx);
  ASSERT_FALSE(hi.ok());
  EXPECT_NE(hi.status().message().find("out of reach"), std::string::npos) << hi.status().message();
  EXPECT_FALSE(choose_for_target(b, "fmf", Target{Target::Kind::max_bytes, 10}, ctx).ok());
  EXPECT_FALSE(choose_for_target(b, "fmf", Target{Target::Kind::ssim, 1.5}, ctx).ok());
  EXPECT_FALSE(choose_for_target(b, "fmf:bogus=1", Target{Target::Kind::psnr, 20}, ctx).ok());
}

TEST(Render, ConstantBtfUnderDirectionalPointAndEnvironmentLight) {
  const float c = 0.25f;
  const Btf b = constant_btf(c);
  RenderSettings s;
  s.light = dir_from_theta_phi(0.5, 1.0);
  auto img = render(b.desc(), btf_evaluator(b), s);
  ASSERT_TRUE(img.ok()) << img.status().message();
  ASSERT_EQ(img->width, 8);
  for (float v : img->rgb) EXPECT_NEAR(v, c, 1e-6);
  // Point light straight above the centre at distance 2: falloff (d / r)^2 at a corner.
  s.light_kind = RenderSettings::LightKind::point;
  s.light = {0, 0, 1};
  img = render(b.desc(), btf_evaluator(b), s);
  const double x = 0.5 - 0.5 / 8, y = (0.5 - 0.5 / 6) * 6.0 / 8;
  EXPECT_NEAR(img->rgb[0], c * 4 / (4 + x * x + y * y), 1e-5);
  // Uniform white environment: radiance = c x (sum of the cell solid angles) = c x 2 pi.
  s.light_kind = RenderSettings::LightKind::environment;
  s.environment = {16, 8, std::vector<float>(16 * 8 * 3, 1.f)};
  img = render(b.desc(), btf_evaluator(b), s);
  for (float v : img->rgb) EXPECT_NEAR(v, c * 2 * k_pi, 1e-4);
}

TEST(Render, SphereLitFromTheCameraCoversTheDisc) {
  const Btf b = constant_btf(1.f);
  RenderSettings s;
  s.shape = RenderSettings::Shape::sphere;
  s.size = 64, s.view = {0, 0, 1}, s.light = {0, 0, 1};
  auto img = render(b.desc(), btf_evaluator(b), s);
  ASSERT_TRUE(img.ok());
  size_t lit = 0;
  for (size_t k = 0; k < img->rgb.size(); k += 3) lit += img->rgb[k] > 0.5f;
  EXPECT_NEAR(double(lit) / (64.0 * 64.0), k_pi / 4, 0.01);
  EXPECT_EQ(img->rgb[0], 0.f);  // corner: background
}

TEST(Render, SphereTextureIsContinuousWhereverTheCameraLooks) {
  // A ramp across the texture (value = (x + 0.5) / width, the same for every direction): on
  // the visible sphere it must change smoothly. Seen from the top, the old mapping put a
  // texture pole at the disc's centre, where every column met (a pinwheel: neighbouring pixels
  // differed by up to the whole ramp).
  Btf b = constant_btf(0.f, 16, 8);
  const BtfDesc& d = b.desc();
  for (int y = 0; y < d.height; ++y)
    for (int x = 0; x < d.width; ++x) std::fill_n(b.abrdf(size_t(y) * 16 + size_t(x)), d.abrdf_size(), (x + 0.5f) / 16);
  for (const Vec3& view : {Vec3{0, 0, 1}, dir_from_theta_phi(0.8, 2.0)}) {
    RenderSettings s;
    s.shape = RenderSettings::Shape::sphere;
    s.size = 64, s.view = view, s.light = view;
    auto img = render(d, btf_evaluator(b), s);
    ASSERT_TRUE(img.ok()) << img.status().message();
    // Within 0.7 of the radius: one pixel moves the texture by at most 16 / (pi 32 cos) texels
    // horizontally (cos >= 0.71), the ramp 1/16 per texel; the BTF is constant in direction, so
    // the light (from the camera) only scales by the local cosine, which changes slowly.
    double jump = 0, seen = 0;
    for (int j = 0; j < 64; ++j)
      for (int i = 0; i + 1 < 64; ++i) {
        const double px = (i + 0.5) / 32 - 1, py = 1 - (j + 0.5) / 32;
        if (px * px + py * py > 0.49 || std::pow(px + 1.0 / 32, 2) + py * py > 0.49) continue;
        const size_t k = (size_t(j) * 64 + size_t(i)) * 3;
        jump = std::max(jump, double(std::abs(img->rgb[k + 3] - img->rgb[k])));
        seen = std::max(seen, double(img->rgb[k]));
      }
    ASSERT_GT(seen, 0.2);
    EXPECT_LT(jump, 0.03) << "view " << view.x << " " << view.y << " " << view.z;
  }
}

TEST(Render, ToneMapKeepsHighlightsBelowWhite) {
  RgbImage im{2, 1, {0.5f, 0.5f, 0.5f, 100.f, 50.f, 10.f}};
  tone_map(im, 1.0, ToneMap::none);  // one stop up
  EXPECT_FLOAT_EQ(im.rgb[0], 1.0f);
  EXPECT_FLOAT_EQ(im.rgb[3], 200.f);
  tone_map(im, 0.0, ToneMap::reinhard);
  const float L = 0.2126f * im.rgb[3] + 0.7152f * im.rgb[4] + 0.0722f * im.rgb[5];
  EXPECT_LT(L, 1.0f);
  EXPECT_GT(L, 0.95f);
  EXPECT_NEAR(im.rgb[3] / im.rgb[5], 10.0, 1e-4);  // colour kept
  EXPECT_NEAR(im.rgb[0], 0.5f, 1e-6);               // L = 1 -> 1 / 2
}

TEST(Render, ModelRendersLikeItsDataAndEnvironmentMatchesLpcaRelight) {
  const Btf b = small_btf(10, 10);
  auto r = resolve_spec("lpca:clusters=1:components=60:precision=float:sh_order=12");
  Context ctx;
  auto m = r->first->encode(b, r->second, ctx);
  ASSERT_TRUE(m.ok()) << m.status().message();
  RenderSettings s;
  s.light_kind = RenderSettings::LightKind::environment;
  s.view = dir_from_theta_phi(0.4, 0.7);
  s.environment.width = 64, s.environment.height = 32;
  for (int j = 0; j < 32; ++j)  // smooth sky: brighter towards the zenith and towards +x
    for (int i = 0; i < 64; ++i) {
      const double th = k_pi * (j + 0.5) / 32, ph = 2 * k_pi * (i + 0.5) / 64;
      const float v = float(1 + std::cos(th) + 0.5 * std::sin(th) * std::cos(ph));
      s.environment.rgb.insert(s.environment.rgb.end(), {v, 0.8f * v, 0.6f * v});
    }
  auto data = render(b.desc(), btf_evaluator(b), s);
  auto model = render(b.desc(), model_evaluator(*m.value()), s);
  ASSERT_TRUE(data.ok() && model.ok());
  EXPECT_GT(render_ssim(data.value(), model.value()), 0.99);
  // Brute-force quadrature over the measured lights vs lpca's SH relighting of the same lighting.
  auto env = project_latlong(s.environment.rgb.data(), 64, 32, 12);
  ASSERT_TRUE(env.ok());
  int w = 0, h = 0;
  auto relit = relight(*m.value(), env.value(), s.view, w, h);
  ASSERT_TRUE(relit.ok()) << relit.status().message();
  double num = 0, den = 0;
  for (size_t k = 0; k < relit->size(); ++k) {
    num += std::pow(double((*relit)[k]) - model->rgb[k], 2);
    den += std::pow(double(model->rgb[k]), 2);
  }
  const double rel = std::sqrt(num / den);
  std::printf("environment render vs SH relight (order 12): relative L2 %.3e\n", rel);
  // Measured 9.1e-4: the bilinear lookup of the 64 x 32 map vs its exact SH projection.
  EXPECT_LE(rel, 1.1e-3);
  EXPECT_GE(rel, 0.75 * 1.1e-3);
}

TEST(Render, BadInputsAreErrors) {
  const Btf b = constant_btf(1.f);
  RenderSettings s;
  s.view = {0, 0.5f, -0.8f};
  EXPECT_FALSE(render(b.desc(), btf_evaluator(b), s).ok());  // below the horizon
  s.view = {0, 0, 1};
  s.light_kind = RenderSettings::LightKind::environment;
  EXPECT_FALSE(render(b.desc(), btf_evaluator(b), s).ok());  // no environment
  s.environment = {2, 1, {1, 1, NAN, 1, 1, 1}};
  EXPECT_FALSE(render(b.desc(), btf_evaluator(b), s).ok());
  RgbImage a{2, 2, std::vector<float>(12, 0.5f)};
  const RgbImage sbs = side_by_side(a, a, 5);
  EXPECT_EQ(sbs.width, 3 * 2 + 8);
  EXPECT_EQ(render_ssim(a, a), 1.0);
}
