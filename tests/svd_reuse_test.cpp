// core/svd.h's reuse of decompositions during a byte-budget search (RandomizedSvdReuse,
// ExactSvdReuse): a later request is served from a kept factorization, Gram eigenpairs or
// projection panels, with the bits (or within the bounds) of the same request made alone.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <vector>

#include "core/svd.h"
#include "tests/svd_test_util.h"

namespace btfc {
namespace {

using test::actual_rel_error;
using test::slow_decay_matrix;
using test::test_matrix;

TEST(Svd, RandomizedReuseServesTheLeadingComponentsOfALargerFactorization) {
  // Inside a RandomizedSvdReuse scope (a byte-budget search), a randomized request of rank C
  // with truncation_ok is served as the leading C components of one factorization at
  // 2 C rounded up to 64 (128 for C = 40), kept for later requests up to that rank; a larger
  // request computes a new one (doubling). The served components are exactly the larger
  // factorization's, and their error is within 1 % of the Eckart-Young optimum.
  const size_t m = 1100, n = 1500;
  Eigen::VectorXd sigma;
  const std::vector<float> b = slow_decay_matrix(m, n, 9, sigma);
  auto optimum = [&](int C) { return std::sqrt(sigma.tail(sigma.size() - C).squaredNorm() / sigma.squaredNorm()); };
  SvdOptions o;
  o.method = SvdMethod::randomized, o.truncation_ok = true;
  o.max_rank = 128;
  auto direct128 = truncated_svd(b.data(), m, n, o);  // no scope: computed as asked
  ASSERT_TRUE(direct128.ok());
  ASSERT_EQ(direct128->S.size(), 128);
  const size_t computed0 = RandomizedSvdReuse::computed(), served0 = RandomizedSvdReuse::served();
  EXPECT_EQ(RandomizedSvdReuse::served(), served0) << "nothing served outside a scope";
  {
    const RandomizedSvdReuse scope(256);
    for (int C : {40, 100, 128}) {
      o.max_rank = C;
      auto r = truncated_svd(b.data(), m, n, o);
      ASSERT_TRUE(r.ok());
      ASSERT_EQ(r->S.size(), C);
      EXPECT_EQ(r->requested_rank, C);
      EXPECT_EQ((r->U - direct128->U.leftCols(C)).cwiseAbs().maxCoeff(), 0.0f) << C;
      EXPECT_EQ((r->SxV - direct128->SxV.leftCols(C)).cwiseAbs().maxCoeff(), 0.0f) << C;
      EXPECT_EQ((r->S - direct128->S.head(C)).cwiseAbs().maxCoeff(), 0.0) << C;
      const double err = actual_rel_error(b, m, n, *r);
      std::printf("rank %d from rank 128: error %.6f, optimum %.6f\n", C, err, optimum(C));
      EXPECT_LE(err, 1.01 * optimum(C)) << C;
      EXPECT_GE(err, 0.9999 * optimum(C)) << C;
      EXPECT_NEAR(r->rel_error_estimate(), err, 1e-3 * err) << C;
    }
    EXPECT_EQ(RandomizedSvdReuse::computed() - computed0, 1u) << "one factorization for the three";
    EXPECT_EQ(RandomizedSvdReuse::served() - served0, 3u);
    o.max_rank = 200;  // above the kept 128: a new one at min(256, 400)
    auto r200 = truncated_svd(b.data(), m, n, o);
    ASSERT_TRUE(r200.ok());
    EXPECT_EQ(r200->S.size(), 200);
    EXPECT_EQ(RandomizedSvdReuse::computed() - computed0, 2u);
    EXPECT_LE(actual_rel_error(b, m, n, *r200), 1.01 * optimum(200));
    o.max_rank = 300;  // above the scope's rank: computed as asked
    auto r300 = truncated_svd(b.data(), m, n, o);
    ASSERT_TRUE(r300.ok());
    EXPECT_EQ(r300->S.size(), 300);
    o.truncation_ok = false;
    o.max_rank = 40;  // the caller does not allow it: computed as asked
    auto own = truncated_svd(b.data(), m, n, o);
    ASSERT_TRUE(own.ok());
    EXPECT_EQ(RandomizedSvdReuse::served() - served0, 4u);
    EXPECT_EQ(RandomizedSvdReuse::computed() - computed0, 2u);
  }
  o.truncation_ok = true;
  auto after = truncated_svd(b.data(), m, n, o);  // the scope is gone, and what it kept
  ASSERT_TRUE(after.ok());
  EXPECT_EQ(RandomizedSvdReuse::served() - served0, 4u);
  EXPECT_EQ(RandomizedSvdReuse::computed() - computed0, 2u);
}

TEST(Svd, InASearchARandomizedRankIsProjectedFromTheKeptExactGram) {
  // A byte-budget search holds both scopes. Once a probe's rank was factorized exactly (its Gram
  // eigenpairs kept, ExactSvdReuse), a later probe whose rank the automatic choice factorizes
  // randomized, and which the kept randomized factorization does not cover, is served by the
  // exact path from those eigenpairs (a projection: no randomized SVD). The result is the exact
  // SVD at that rank, bit for bit.
  const size_t m = 1300, n = 1100;  // small side 1100: randomized at rank 32, exact from rank 122
  const std::vector<float> b = test_matrix(m, n, 60, 4);
  SvdOptions exact;
  exact.method = SvdMethod::exact;
  exact.max_rank = 100;
  auto plain100 = truncated_svd(b.data(), m, n, exact);  // no scope
  ASSERT_TRUE(plain100.ok());
  SvdOptions o;  // automatic, as fmf's probes ask
  o.truncation_ok = true;
  const size_t reuses0 = ExactSvdReuse::reuses(), computed0 = RandomizedSvdReuse::computed();
  {
    const ExactSvdReuse keep_gram;
    const RandomizedSvdReuse keep_randomized(512);
    o.max_rank = 32;  // no exact probe yet: randomized, kept at rank 64 (grown_rank)
    auto first = truncated_svd(b.data(), m, n, o);
    ASSERT_TRUE(first.ok());
    EXPECT_EQ(first->method, "randomized");
    EXPECT_EQ(RandomizedSvdReuse::computed() - computed0, 1u);
    o.max_rank = 300;  // resolved exact: its Gram eigenpairs are kept
    auto high = truncated_svd(b.data(), m, n, o);
    ASSERT_TRUE(high.ok());
    EXPECT_EQ(high->method, "exact");
    o.max_rank = 100;  // randomized by the automatic choice, above the kept randomized rank
    ASSERT_EQ(resolved_method(m, n, o), SvdMethod::randomized);
    auto r100 = truncated_svd(b.data(), m, n, o);
    ASSERT_TRUE(r100.ok());
    EXPECT_EQ(r100->method, "exact");
    EXPECT_EQ(ExactSvdReuse::reuses() - reuses0, 1u) << "served from the kept eigenpairs";
    EXPECT_EQ(RandomizedSvdReuse::computed() - computed0, 1u) << "no randomized SVD for it";
    EXPECT_EQ(r100->U, plain100->U);  // the exact SVD
    EXPECT_EQ(r100->SxV, plain100->SxV);
    o.max_rank = 40;  // covered by the kept randomized factorization: served from it, as before
    auto r32 = truncated_svd(b.data(), m, n, o);
    ASSERT_TRUE(r32.ok());
    EXPECT_EQ(r32->method, "randomized");
    o.method = SvdMethod::randomized, o.max_rank = 100;  // asked for by name: randomized
    auto named = truncated_svd(b.data(), m, n, o);
    ASSERT_TRUE(named.ok());
    EXPECT_EQ(named->method, "randomized");
    EXPECT_EQ(ExactSvdReuse::reuses() - reuses0, 1u);
    o.method = SvdMethod::automatic;
  }
  auto after = truncated_svd(b.data(), m, n, o);  // the scopes are gone: the automatic choice again
  ASSERT_TRUE(after.ok());
  EXPECT_EQ(after->method, "randomized");
}

TEST(Svd, InASearchARankWhoseGrowthTheRandomizedPathCapsIsFactorizedExactly) {
  // Inside both scopes, a randomized request whose grown rank (twice itself, rounded up to 64)
  // the randomized path cannot reach (small side 1100: randomized up to rank 121) is factorized
  // exactly, its Gram eigenpairs kept for later ranks; with the randomized scope alone, grown
  // to the cap as before. A non-finite value is still an error (the randomized path's check).
  const size_t m = 1300, n = 1100;
  std::vector<float> b = test_matrix(m, n, 60, 4);
  SvdOptions o;
  o.truncation_ok = true;
  o.max_rank = 100;  // grown: 256 wanted, 121 reachable
  ASSERT_EQ(resolved_method(m, n, o), SvdMethod::randomized);
  const size_t computed0 = RandomizedSvdReuse::computed(), reuses0 = ExactSvdReuse::reuses();
  {
    const RandomizedSvdReuse keep_randomized(512);
    auto r = truncated_svd(b.data(), m, n, o);
    ASSERT_TRUE(r.ok());
    EXPECT_EQ(r->method, "randomized") << "no exact scope: grown to the cap";
    EXPECT_EQ(RandomizedSvdReuse::computed() - computed0, 1u);
  }
  {
    const ExactSvdReuse keep_gram;
    const RandomizedSvdReuse keep_randomized(512);
    o.max_rank = 30;  // wanted 64: reachable, randomized as before (kept at 64)
    auto low = truncated_svd(b.data(), m, n, o);
    ASSERT_TRUE(low.ok());
    EXPECT_EQ(low->method, "randomized");
    EXPECT_EQ(RandomizedSvdReuse::computed() - computed0, 2u);
    o.max_rank = 50;  // covered by the kept one
    auto covered = truncated_svd(b.data(), m, n, o);
    ASSERT_TRUE(covered.ok());
    EXPECT_EQ(covered->method, "randomized");
    std::vector<float> c = b;  // another matrix: nothing kept for it
    c[3] += 1.0f;
    o.max_rank = 100;
    auto r = truncated_svd(c.data(), m, n, o);
    ASSERT_TRUE(r.ok());
    EXPECT_EQ(r->method, "exact") << "the growth is capped: exact, its Gram kept";
    EXPECT_EQ(RandomizedSvdReuse::computed() - computed0, 2u);
    o.max_rank = 110;
    auto again = truncated_svd(c.data(), m, n, o);
    ASSERT_TRUE(again.ok());
    EXPECT_EQ(again->method, "exact");
    EXPECT_EQ(ExactSvdReuse::reuses() - reuses0, 1u);
    c[7] = std::numeric_limits<float>::quiet_NaN();
    auto bad = truncated_svd(c.data(), m, n, o);
    ASSERT_FALSE(bad.ok());
    EXPECT_EQ(bad.status().code(), StatusCode::corrupt_data) << bad.status().message();
    // The same rule for a set of matrices (color=dfmf's stream): the caller is told.
    auto randomized_at = [](int r) { return r <= 121; };
    EXPECT_TRUE(RandomizedSvdReuse::grows_past_randomized(42, {100, 4, 4}, randomized_at));
    EXPECT_FALSE(RandomizedSvdReuse::grows_past_randomized(42, {30, 4, 4}, randomized_at));
  }
  const RandomizedSvdReuse keep_randomized(512);  // no exact scope: never
  EXPECT_FALSE(RandomizedSvdReuse::grows_past_randomized(42, {100, 4, 4}, [](int r) { return r <= 121; }));
}

TEST(Svd, ReuseServesAnExactSvdAgainAtAnotherRankWithTheSameResult) {
  const size_t m = 300, n = 200;
  const std::vector<float> b = test_matrix(m, n, 20, 5);
  SvdOptions o;
  o.method = SvdMethod::exact;
  o.max_rank = 12;
  auto plain12 = truncated_svd(b.data(), m, n, o);
  ASSERT_TRUE(plain12.ok());
  const size_t before = ExactSvdReuse::reuses();
  {
    const ExactSvdReuse reuse;
    o.max_rank = 20;
    ASSERT_TRUE(truncated_svd(b.data(), m, n, o).ok());
    o.max_rank = 12;
    auto again = truncated_svd(b.data(), m, n, o);
    ASSERT_TRUE(again.ok());
    EXPECT_EQ(ExactSvdReuse::reuses(), before + 1);
    EXPECT_EQ(again->U, plain12->U);  // bit for bit: the same decomposition, truncated
    EXPECT_EQ(again->SxV, plain12->SxV);
    // Other content (one value changed): not reused.
    std::vector<float> c = b;
    c[17] += 1.0f;
    ASSERT_TRUE(truncated_svd(c.data(), m, n, o).ok());
    EXPECT_EQ(ExactSvdReuse::reuses(), before + 1);
  }
  // Outside a scope nothing is kept.
  ASSERT_TRUE(truncated_svd(b.data(), m, n, o).ok());
  EXPECT_EQ(ExactSvdReuse::reuses(), before + 1);
}

TEST(Svd, ReuseKeepsTheProjectionByPanelsWithTheBitsOfEachRankAlone) {
  // Both orientations (SxV = B^T E where the rows are the small side, U = B E / sigma where the
  // columns are), ranks across several 32-column panels, asked in a search's order: large, smaller,
  // larger. Each must equal the same rank factorized alone, bit for bit, and only new panels are
  // projected.
  for (const auto& [m, n] : {std::pair<size_t, size_t>{150, 220}, {230, 140}}) {
    const std::vector<float> b = test_matrix(m, n, 120, 11);
    SvdOptions o;
    o.method = SvdMethod::exact;
    std::map<int, SvdResult> alone;
    for (int rank : {70, 40, 101, 96}) {
      o.max_rank = rank;
      auto r = truncated_svd(b.data(), m, n, o);
      ASSERT_TRUE(r.ok());
      ASSERT_EQ(r->U.cols(), rank);
      alone[rank] = std::move(r).value();
    }
    const ExactSvdReuse reuse;
    const size_t cols0 = ExactSvdReuse::projected_columns();
    const size_t expect_cols[] = {96, 96, 128, 128};  // panels for 70, none for 40, one for 101, none for 96
    int step = 0;
    for (int rank : {70, 40, 101, 96}) {
      o.max_rank = rank;
      auto r = truncated_svd(b.data(), m, n, o);
      ASSERT_TRUE(r.ok());
      EXPECT_EQ(ExactSvdReuse::projected_columns() - cols0, expect_cols[step++]) << m << " x " << n << " rank " << rank;
      EXPECT_EQ(r->U, alone[rank].U) << m << " x " << n << " rank " << rank;
      EXPECT_EQ(r->SxV, alone[rank].SxV) << m << " x " << n << " rank " << rank;
      EXPECT_EQ(r->S, alone[rank].S);
    }
  }
}

}  // namespace
}  // namespace btfc
