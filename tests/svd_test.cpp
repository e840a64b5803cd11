// core/svd.h: the exact path's LAPACK eigensolver against Eigen's (the reference), the automatic
// choice of path, the passes' products and sketches against their references, and the two
// randomized schemes (block Krylov, power iterations) against the Eckart-Young optimum. The reuse
// of decompositions during a byte-budget search: svd_reuse_test.cpp.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <omp.h>
#include <cmath>
#include <limits>
#include <cstdio>
#include <cstring>
#include <memory>
#include <map>
#include <random>
#include <tuple>
#include <string>

#include "core/cpu_dispatch.h"
#include "core/sparse_sketch.h"
#include "core/svd.h"
#include "core/thin_product.h"
#include "tests/svd_test_util.h"

namespace btfc {
namespace {

using test::actual_rel_error;
using test::slow_decay_matrix;
using test::test_matrix;

TEST(Svd, BlockKrylovIsWithinOnePercentOfEckartYoungInFewerPasses) {
  // 600 columns: a dense Gaussian first block; 1500 columns (>= 4 x 256): the sparse sign sketch.
  for (auto [m, n] : {std::pair<size_t, size_t>{600, 1500}, {1500, 600}}) {
  Eigen::VectorXd sigma;
  const std::vector<float> b = slow_decay_matrix(m, n, 7, sigma);
  for (int C : {8, 32}) {
    const double optimum = std::sqrt(sigma.tail(sigma.size() - C).squaredNorm() / sigma.squaredNorm());
    SvdOptions o;
    o.max_rank = C, o.oversample = 16, o.power_iters = 4, o.method = SvdMethod::randomized;
    auto krylov = truncated_svd(b.data(), m, n, o);
    ASSERT_TRUE(krylov.ok());
    // Power iterations with the passes the Krylov run took (2 per block = 2q + 2).
    o.scheme = RandomizedScheme::power, o.power_iters = krylov->iterations - 1;
    auto power = truncated_svd(b.data(), m, n, o);
    ASSERT_TRUE(power.ok());
    EXPECT_EQ(krylov->method, "randomized");
    const double ek = actual_rel_error(b, m, n, *krylov), ep = actual_rel_error(b, m, n, *power);
    std::printf("%zu x %zu, rank %d: optimum %.6f, block Krylov %.6f (%d blocks, %s start), power iterations in as many passes %.6f\n",
                m, n, C, optimum, ek, krylov->iterations, krylov->sparse_start ? "sparse" : "Gaussian", ep);
    EXPECT_EQ(krylov->sparse_start, n >= 1024);
    EXPECT_GE(ek / optimum, 1 - 1e-4) << "cannot beat Eckart-Young";
    EXPECT_LE(ek / optimum, 1.01) << "rank " << C;
    EXPECT_LE(krylov->iterations, 5);
    // As accurate as the power scheme in as many passes (to 1e-4 of the error), though its
    // passes after the first block are C columns wide and the power scheme's all C + 16.
    EXPECT_LE(ek, ep * (1 + 1e-4));
    // The estimate is the actual error of U SxV^T (an orthogonal projection of B's rows).
    EXPECT_NEAR(krylov->rel_error_estimate(), ek, 1e-4 * ek);
    // U orthonormal; singular values descending and equal to the data's to the error's order.
    const Eigen::MatrixXd UtU = krylov->U.cast<double>().transpose() * krylov->U.cast<double>();
    EXPECT_LT((UtU - Eigen::MatrixXd::Identity(C, C)).cwiseAbs().maxCoeff(), 1e-5);
    for (int i = 0; i < C; ++i) EXPECT_NEAR(krylov->S(i), sigma(i), 0.02 * sigma(i)) << i;
  }
  }
}

// The sparse start at the extremes (B wide enough for it: 1200 columns): zeros, a constant,
// rank-deficient data, and HDR rows spanning 1e-6 .. 1e6, against the exact SVD. The constant
// matrix once came out as -B (error 2: its exhausted Krylov blocks re-entered the basis as
// copies of the constant direction, orthonormalize_against).
TEST(Svd, SparseStartHoldsAtTheExtremes) {
  const size_t m = 300, n = 1200;
  for (const auto& c : test::extreme_matrices(m, n, 21)) {
    SvdOptions o;
    o.max_rank = 8, o.oversample = 8, o.power_iters = 3, o.method = SvdMethod::randomized;
    auto r = truncated_svd(c.b.data(), m, n, o);
    ASSERT_TRUE(r.ok()) << c.name;
    EXPECT_TRUE(r->sparse_start) << c.name;
    o.method = SvdMethod::exact;
    auto exact = truncated_svd(c.b.data(), m, n, o);
    ASSERT_TRUE(exact.ok());
    test::expect_like_exact(c, m, n, *r, *exact, c.name);
  }
}

// The sparse sign sketch W = S^T B (core/sparse_sketch.h) against its one-value-at-a-time
// reference (bit for bit: the same sums in the same order) and against S^T B formed from the map
// in double; every row in exactly one bucket; the energy against squared_norm.
TEST(Svd, SparseSignSketchEqualsTheReference) {
  std::mt19937_64 rng(12);
  std::uniform_real_distribution<float> u(-1.f, 1.f);
  // Rows: one, less than a group, a group's tail, whole and partial blocks (16 G rows), large.
  for (size_t m : {1, 15, 16, 17, 255, 256, 257, 1000, 4099}) {
    for (size_t s : {16, 256, 320, 384, 1024}) {
      const size_t n = 67;
      std::vector<float> b(m * n);
      for (float& x : b) x = u(rng);
      const SparseSign S = make_sparse_sign(m, s, 3, 2);
      ASSERT_EQ(S.s, s);
      ASSERT_EQ(S.layers, 2u);
      std::vector<float> w(s * n, -1.f), w_ref(s * n, -2.f);
      double e = -1, e_ref = -1;
      sparse_sign_product(b.data(), n, S, w.data(), &e);
      sparse_sign_product_reference(b.data(), n, S, w_ref.data(), &e_ref);
      ASSERT_EQ(0, std::memcmp(w.data(), w_ref.data(), w.size() * sizeof(float))) << m << " " << s;
      std::vector<float> w2(s * n, -3.f);  // the AVX2 loop too, where the CPU has it
      double e2 = -1;
      if (sparse_sign_product_avx2(b.data(), n, S, w2.data(), &e2)) {
        ASSERT_EQ(0, std::memcmp(w2.data(), w_ref.data(), w.size() * sizeof(float))) << "AVX2 " << m << " " << s;
        EXPECT_NEAR(e2, e_ref, 1e-12 * e_ref + 1e-30) << "AVX2 " << m << " " << s;
      }
      const double total = squared_norm(b.data(), b.size());
      EXPECT_NEAR(e, total, 1e-12 * total) << m << " " << s;
      EXPECT_NEAR(e_ref, total, 1e-12 * total);
      // The map: row i -> (bucket, sign) per layer; per layer each row once, each bucket group one
      // row group per block (a row may meet the same bucket in two layers: the entries add).
      const size_t groups = s / 16, q_all = (m + 15) / 16;
      Eigen::MatrixXd St = Eigen::MatrixXd::Zero(Eigen::Index(s), Eigen::Index(m));
      for (size_t t = 0; t < S.layers; ++t) {
        std::vector<int> seen(q_all, 0);
        for (size_t i = 0; i < q_all; ++i) {
          const size_t k = i % groups, q = i - k + S.pick[t * q_all + i];
          ASSERT_LT(q, q_all);
          ++seen[q];
          const uint16_t neg = S.negative[t * q_all + q];
          for (size_t r = 0; r < 16 && 16 * q + r < m; ++r) St(Eigen::Index(16 * k + r), Eigen::Index(16 * q + r)) += (neg >> r) & 1 ? -1 : 1;
        }
        for (size_t q = 0; q < q_all; ++q) ASSERT_EQ(seen[q], 1) << "layer " << t << " row group " << q;
      }
      Eigen::Map<const Eigen::MatrixXf> B(b.data(), Eigen::Index(m), Eigen::Index(n));
      const Eigen::MatrixXd ref = St * B.cast<double>();
      Eigen::Map<const Eigen::MatrixXf> W(w.data(), Eigen::Index(s), Eigen::Index(n));
      EXPECT_LT((W.cast<double>() - ref).cwiseAbs().maxCoeff(), 1e-6 * double(m)) << m << " " << s;
    }
  }
  // The same seed gives the same map; another seed another one.
  const SparseSign a = make_sparse_sign(5000, 256, 1, 4), b2 = make_sparse_sign(5000, 256, 1, 4), c = make_sparse_sign(5000, 256, 2, 4);
  EXPECT_EQ(a.pick, b2.pick);
  EXPECT_EQ(a.negative, b2.negative);
  EXPECT_NE(a.negative, c.negative);
}

// The column sketch W = B S (the in-core Krylov's first block) on a block of rows of a taller
// matrix, against the row sketch of that block's transpose, (S^T B^T)^T, from its reference (the
// same sums in another order: to round-off); the same bits on one thread and on all; the energy
// against squared_norm; texel order (4096 rows and more) against bucket order (fewer). Rows
// across the bucket order's 2048-row tasks and texel order's chunks (4 of 1136 rows and a short
// one at 4500; 8 at 33000, over 4 x 8192); one and two layers.
TEST(Svd, ColumnSketchEqualsTheRowSketchOfTheTranspose) {
  std::mt19937_64 rng(13);
  std::uniform_real_distribution<float> u(-1.f, 1.f);
  for (size_t n : {1, 15, 17, 257, 1000, 4099}) {
    for (size_t m : {1, 7, 2049, 4500, 33000}) {
      if (m == 33000 && n > 17) continue;  // the test's size
      for (size_t s : {16, 256, 1024}) {
        const size_t layers = s == 256 ? 2 : 1, ld = m + 5, top = 3;  // rows [top, top + m) of ld
        std::vector<float> b(ld * n);
        for (float& x : b) x = u(rng);
        const SparseSign S = make_sparse_sign(n, s, 5, layers);
        std::vector<float> w(m * s, -1.f), w1(m * s, -2.f), bt(n * m), wr(s * m), block(m * n);
        double e = -1, e1 = -1, er = -1;
        sparse_sign_columns(b.data() + top, ld, m, n, S, w.data(), &e);
        const int threads = omp_get_max_threads();
        omp_set_num_threads(1);
        sparse_sign_columns(b.data() + top, ld, m, n, S, w1.data(), &e1);
        omp_set_num_threads(threads);
        ASSERT_EQ(0, std::memcmp(w.data(), w1.data(), w.size() * sizeof(float))) << n << " " << m << " " << s;
        EXPECT_EQ(e, e1);
        if (m >= 4096) {  // texel order (4096 rows and more) and bucket order (two calls of fewer rows): the same bits
          for (size_t i0 : {size_t(0), size_t(2000)}) {
            const size_t h = i0 == 0 ? 2000 : m - 2000;
            std::vector<float> part(h * s);
            sparse_sign_columns(b.data() + top + i0, ld, h, n, S, part.data());
            for (size_t c = 0; c < s; ++c)
              ASSERT_EQ(0, std::memcmp(part.data() + c * h, w.data() + c * m + i0, h * sizeof(float))) << n << " " << s << " " << c;
          }
        }
        for (size_t j = 0; j < n; ++j)
          for (size_t i = 0; i < m; ++i) bt[i * n + j] = block[j * m + i] = b[j * ld + top + i];
        sparse_sign_product_reference(bt.data(), m, S, wr.data(), &er);
        Eigen::Map<const Eigen::MatrixXf> W(w.data(), Eigen::Index(m), Eigen::Index(s)), Wr(wr.data(), Eigen::Index(s), Eigen::Index(m));
        EXPECT_LT((W.cast<double>() - Wr.transpose().cast<double>()).cwiseAbs().maxCoeff(), 1e-6 * double(n)) << n << " " << m << " " << s;
        const double total = squared_norm(block.data(), block.size());
        EXPECT_NEAR(e, total, 1e-12 * total) << n << " " << m << " " << s;
      }
    }
  }
}

// The whole first pass, Y = B S G (sparse sketch, W G by pieces of rows on the threads): the same
// bits on one thread and on all, within float round-off of (B S) G in double, and the chunks'
// parts (texels [first, first + n) of the sketch's) summing to the whole. Rows span several of
// the sketch's row blocks and W G's pieces.
TEST(Svd, ColumnSketchProductIsThreadCountFreeAndSumsOverChunks) {
  const size_t m = 9000, n = 3000;
  const Eigen::Index l = 48;  // s = 256: row blocks of 562 rows, W G in pieces of 512 and 50
  std::mt19937_64 rng(21);
  std::uniform_real_distribution<float> u(-1.f, 1.f);
  std::vector<float> b(m * n);
  for (float& x : b) x = u(rng);
  SvdOptions o;
  o.seed = 3;
  const Sketch sk = make_column_sketch(n, l, o);
  ASSERT_TRUE(sk.sparse());
  Eigen::MatrixXf y(Eigen::Index(m), l), y1(Eigen::Index(m), l);
  double e = 0, e1 = 0;
  column_sketch_product(b.data(), m, n, sk, y, &e);
  const int threads = omp_get_max_threads();
  omp_set_num_threads(1);
  column_sketch_product(b.data(), m, n, sk, y1, &e1);
  omp_set_num_threads(threads);
  ASSERT_EQ(0, std::memcmp(y.data(), y1.data(), size_t(y.size()) * sizeof(float)));
  EXPECT_EQ(e, e1);
  // Reference: W = B S (each column of B into its bucket, signed), then W G, in double.
  Eigen::MatrixXd w = Eigen::MatrixXd::Zero(Eigen::Index(m), Eigen::Index(sk.S.s));
  std::vector<float> wf(m * sk.S.s);
  sparse_sign_columns(b.data(), m, m, n, sk.S, wf.data());
  for (size_t i = 0; i < wf.size(); ++i) w.data()[i] = wf[i];
  const Eigen::MatrixXd ref = w * sk.G.cast<double>();
  EXPECT_LT((y.cast<double>() - ref).norm(), 1e-5 * ref.norm());
  double energy = 0;
  for (float x : b) energy += double(x) * double(x);
  EXPECT_NEAR(e, energy, 1e-9 * energy);
  // Two chunks of texels sum to the whole (to round-off: each part is its own GEMM).
  Eigen::MatrixXf a(Eigen::Index(m), l), c(Eigen::Index(m), l);
  const size_t split = 1234;
  column_sketch_product(b.data(), m, split, sk, a, nullptr, 0);
  column_sketch_product(b.data() + split * m, m, n - split, sk, c, nullptr, split);
  EXPECT_LT(((a + c) - y).norm(), 1e-5 * y.norm());
  // The streamed first pass: chunks' sums added into one W in order (the bits of the whole's W:
  // each bucket's running sum goes on in texel order), then one W G (pieces of other heights
  // than the row blocks above: equal to round-off).
  ASSERT_EQ(column_sketch_sums_bytes(m, n, l), m * sk.S.s * sizeof(float));
  EXPECT_EQ(column_sketch_sums_bytes(m, 4 * sk.S.s - 1, l), 0u);  // too few texels: the dense sketch
  std::vector<float> ws(m * sk.S.s, 0.0f);
  double es = 0;
  for (size_t at : {size_t(0), size_t(700), split, size_t(2999)}) {
    const size_t end = at == 0 ? 700 : at == 700 ? split : at == split ? 2999 : n;
    column_sketch_sums(b.data() + at * m, m, end - at, sk, ws.data(), &es, at);
  }
  ASSERT_EQ(0, std::memcmp(ws.data(), wf.data(), wf.size() * sizeof(float)));
  EXPECT_NEAR(es, energy, 1e-9 * energy);
  Eigen::MatrixXf ys(Eigen::Index(m), l);
  column_sketch_finish(ws.data(), m, sk, ys);
  EXPECT_LT((ys - y).norm(), 1e-6 * y.norm());
  EXPECT_LT((ys.cast<double>() - ref).norm(), 1e-5 * ref.norm());
}

TEST(Svd, BlockKrylovStopsEarlyOnAFastDecayAndHandlesExhaustedRanges) {
  // Rank-60 structure + small noise: the first blocks reach the optimum, later ones add nothing.
  const size_t m = 700, n = 900;
  const std::vector<float> b = test_matrix(m, n, 60, 9);
  SvdOptions o;
  o.max_rank = 16, o.oversample = 16, o.power_iters = 8, o.method = SvdMethod::randomized;
  auto r = truncated_svd(b.data(), m, n, o);
  ASSERT_TRUE(r.ok());
  EXPECT_LT(r->iterations, 9) << "the error-driven stop";
  o.method = SvdMethod::exact;
  auto exact = truncated_svd(b.data(), m, n, o);
  ASSERT_TRUE(exact.ok());
  EXPECT_LE(r->rel_error_estimate() / exact->rel_error_estimate(), 1.01);
  // A zero matrix and a basis as wide as the small side (blocks capped there).
  const std::vector<float> zero(50 * 80, 0.f);
  o.method = SvdMethod::randomized, o.max_rank = 4, o.oversample = 6;
  auto z = truncated_svd(zero.data(), 50, 80, o);
  ASSERT_TRUE(z.ok());
  EXPECT_EQ(z->S.size(), 1);
  EXPECT_EQ(z->SxV.cwiseAbs().maxCoeff(), 0.f);
  EXPECT_TRUE(z->U.allFinite());
  const std::vector<float> small = test_matrix(50, 80, 40, 2);
  auto s = truncated_svd(small.data(), 50, 80, o);
  ASSERT_TRUE(s.ok());
  EXPECT_LE(s->iterations * 10, 50);
  EXPECT_NEAR(s->rel_error_estimate(), actual_rel_error(small, 50, 80, *s), 1e-3);
}

TEST(Svd, KrylovRitzStepHoldsAtAnyDynamicRange) {
  // Singular values falling geometrically so that the kept ones span 1e-1 .. 1e-7 of sigma_1: the
  // Ritz step takes the Gram eigenpairs while sigma_C > 1e-4 sigma_1 and the Householder QR of B P
  // below that; both must give an orthonormal U, the data's singular values and the optimum error.
  const size_t m = 300, n = 500;
  const int C = 12;
  for (double span : {1e-1, 1e-3, 1e-5, 1e-7}) {
    std::mt19937_64 rng(11);
    std::normal_distribution<double> g(0.0, 1.0);
    const Eigen::Index k = Eigen::Index(m);
    Eigen::MatrixXd A(m, k), D(n, k);
    for (Eigen::Index i = 0; i < A.size(); ++i) A.data()[i] = g(rng);
    for (Eigen::Index i = 0; i < D.size(); ++i) D.data()[i] = g(rng);
    const Eigen::MatrixXd U = Eigen::HouseholderQR<Eigen::MatrixXd>(A).householderQ() * Eigen::MatrixXd::Identity(k, k);
    const Eigen::MatrixXd V = Eigen::HouseholderQR<Eigen::MatrixXd>(D).householderQ() * Eigen::MatrixXd::Identity(Eigen::Index(n), k);
    Eigen::VectorXd sigma(k);
    const double q = std::pow(span, 1.0 / (C - 1));
    for (Eigen::Index i = 0; i < k; ++i) sigma(i) = i < C ? std::pow(q, double(i)) : 1e-3 * span / (1.0 + double(i - C));
    const Eigen::MatrixXf Bf = (U * sigma.asDiagonal() * V.transpose()).cast<float>();
    const std::vector<float> b(Bf.data(), Bf.data() + Bf.size());
    SvdOptions o;
    o.max_rank = C, o.oversample = 8, o.power_iters = 3, o.method = SvdMethod::randomized;
    auto r = truncated_svd(b.data(), m, n, o);
    ASSERT_TRUE(r.ok());
    const int kept = int(r->S.size());
    // The numerical-rank floor (sigma > 1e-6 sigma_1) drops the smallest at span 1e-7.
    EXPECT_EQ(kept, span < 1e-6 ? 10 : C) << span;
    const Eigen::MatrixXd UtU = r->U.cast<double>().transpose() * r->U.cast<double>();
    EXPECT_LT((UtU - Eigen::MatrixXd::Identity(kept, kept)).cwiseAbs().maxCoeff(), 1e-5) << span;
    for (int i = 0; i < kept; ++i) EXPECT_NEAR(r->S(i), sigma(i), 1e-3 * sigma(i)) << span << " " << i;
    const double optimum = std::sqrt(sigma.tail(k - kept).squaredNorm() / sigma.squaredNorm());
    const double err = actual_rel_error(b, m, n, *r);
    EXPECT_LE(err, 1.01 * optimum + 1e-6) << span;
  }
}

TEST(Svd, TransposedProductKernelEqualsTheReference) {
  // Every register width (l up to 8 x 16 and a fallback beyond), texel counts that leave tails of
  // the 8- or 16-texel tiles, and more rows than one 2048-row chunk.
  std::mt19937_64 rng(4);
  std::uniform_real_distribution<float> u(-1.f, 1.f);
  int avx2_runs = 0;
  for (auto [m, n] : {std::pair<size_t, size_t>{2500, 203}, {37, 70}}) {
    std::vector<float> b(m * n);
    for (float& x : b) x = u(rng);
    Eigen::Map<const Eigen::MatrixXf> B(b.data(), Eigen::Index(m), Eigen::Index(n));
    for (int l : {1, 5, 8, 16, 17, 24, 25, 32, 33, 48, 80, 100, 128, 130}) {
      Eigen::MatrixXf Y(Eigen::Index(m), l), Z;
      for (Eigen::Index i = 0; i < Y.size(); ++i) Y.data()[i] = u(rng);
      transposed_product(b.data(), m, n, Y, Z);
      const Eigen::MatrixXd ref = B.cast<double>().transpose() * Y.cast<double>();
      ASSERT_EQ(Z.rows(), Eigen::Index(n));
      ASSERT_EQ(Z.cols(), l);
      // Float sums of m products of magnitude <= 1: within m x 2^-24 x a few of the double result.
      EXPECT_LT((Z.cast<double>() - ref).cwiseAbs().maxCoeff(), 4e-7 * double(m)) << "m " << m << " l " << l;
      // The AVX2 kernel (CPUs without AVX-512 run it for l <= 96: one group up to 32, then
      // groups of 24), with the energy sum.
      Eigen::MatrixXf Z2;
      double e2 = -1;
      if (transposed_product_avx2(b.data(), m, n, Y, Z2, &e2)) {
        ASSERT_LE(l, 96);
        ASSERT_EQ(Z2.rows(), Eigen::Index(n));
        EXPECT_LT((Z2.cast<double>() - ref).cwiseAbs().maxCoeff(), 4e-7 * double(m)) << "avx2, m " << m << " l " << l;
        EXPECT_NEAR(e2, B.cast<double>().squaredNorm(), 1e-12 * B.cast<double>().squaredNorm());
        ++avx2_runs;
      }
    }
  }
  if (cpu_has_avx2_fma()) {
    EXPECT_EQ(avx2_runs, 2 * 11) << "every l <= 96, both shapes";
  }
}

TEST(Svd, ThinProductKernelEqualsTheReference) {
  // Y = B X: both column-group widths (8, 12) and their padding, l past the kernel's 128 (the
  // Eigen fallback), rows that leave a tail below the 32-row tile, more rows than one 1024-row
  // task, texels past one 128-texel chunk, and fewer rows than a tile.
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<float> u(-1.f, 1.f);
  int tile_runs = 0, avx2_runs = 0;
  for (auto [m, n] : {std::pair<size_t, size_t>{2500, 203}, {37, 70}, {20, 9}, {1024, 1}}) {
    std::vector<float> b(m * n);
    for (float& x : b) x = u(rng);
    Eigen::Map<const Eigen::MatrixXf> B(b.data(), Eigen::Index(m), Eigen::Index(n));
    for (int l : {1, 5, 8, 12, 13, 24, 33, 48, 80, 100, 128, 130}) {
      Eigen::MatrixXf X(Eigen::Index(n), l), Y;
      for (Eigen::Index i = 0; i < X.size(); ++i) X.data()[i] = u(rng);
      thin_product(b.data(), m, n, X, Y);
      const Eigen::MatrixXd ref = B.cast<double>() * X.cast<double>();
      ASSERT_EQ(Y.rows(), Eigen::Index(m));
      ASSERT_EQ(Y.cols(), l);
      EXPECT_LT((Y.cast<double>() - ref).cwiseAbs().maxCoeff(), 4e-7 * double(n) + 1e-6) << "m " << m << " n " << n << " l " << l;
      // The AVX-512 tiles themselves, also on Intel CPUs (whose thin_product takes OpenBLAS).
      if (thin_product_tiles(b.data(), m, n, X, Y)) {
        ++tile_runs;
        EXPECT_LT((Y.cast<double>() - ref).cwiseAbs().maxCoeff(), 4e-7 * double(n) + 1e-6) << "tiles, m " << m << " n " << n << " l " << l;
      }
      // The AVX2 tiles (Zen 1 CPUs run them) on any CPU with AVX2: 6 columns by 16 rows or 4 by
      // 24, which pads l less, so both tile shapes and their row tails (37 rows: 5, 13) are met.
      if (thin_product_avx2(b.data(), m, n, X, Y)) {
        ++avx2_runs;
        EXPECT_LT((Y.cast<double>() - ref).cwiseAbs().maxCoeff(), 4e-7 * double(n) + 1e-6) << "avx2, m " << m << " n " << n << " l " << l;
      }
    }
  }
  if (cpu_has_avx512f()) {
    EXPECT_EQ(tile_runs, 3 * 11) << "every l <= 128 with m >= 32 rows";
  }
  if (cpu_has_avx2_fma()) {
    EXPECT_EQ(avx2_runs, 3 * 11) << "every l <= 128 with m >= 24 rows";
  }
  // No texels: a zero product (the kernels' loops would leave their staging unwritten).
  {
    const std::vector<float> none;
    Eigen::MatrixXf X(0, 48), Y;
    thin_product(none.data(), 100, 0, X, Y);
    ASSERT_EQ(Y.rows(), 100);
    EXPECT_EQ(Y.cwiseAbs().maxCoeff(), 0.f);
    Eigen::MatrixXf Yin = Eigen::MatrixXf::Ones(100, 48), Z;
    double e = -1;
    transposed_product(none.data(), 100, 0, Yin, Z, &e);
    EXPECT_EQ(Z.rows(), 0);
    EXPECT_EQ(e, 0.0);
  }
  // The energy pass: the double sum of squares, over a length that is not a multiple of a block.
  std::vector<float> v(3 * (size_t(1) << 20) + 7);
  double ref = 0;
  for (float& x : v) x = u(rng), ref += double(x) * double(x);
  EXPECT_NEAR(squared_norm(v.data(), v.size()), ref, 1e-12 * ref);
}

// Matrices stacked in B's rows (color=dfmf's channels in a texel's column), sketched in one call
// with `segment`: W is each matrix's own sums stacked, bit for bit, and energy[k] matrix k's
// ||.||_F^2, with segments ending within the texel order's row chunks (3 x 1500 rows) and in the
// bucket order (3 x 41).
TEST(Svd, StackedColumnSketchSumsEachMatrixApart) {
  std::mt19937_64 rng(8);
  std::uniform_real_distribution<float> u(-1.f, 1.f);
  const size_t n = 1300;
  SvdOptions opt;
  const Sketch sketch = make_column_sketch(n, 12, opt);
  ASSERT_TRUE(sketch.sparse());
  const size_t s = sketch.S.s;
  for (size_t m : {size_t(41), size_t(1500)}) {
    std::vector<float> b(3 * m * n);
    for (float& x : b) x = u(rng) * 3.f;
    std::vector<float> w(3 * m * s, 0.0f), wi(m * s);
    double e[3] = {0, 0, 0};
    column_sketch_sums(b.data(), 3 * m, n, sketch, w.data(), e, 0, 0, m);
    for (size_t k = 0; k < 3; ++k) {
      std::fill(wi.begin(), wi.end(), 0.0f);
      double ek = 0;
      column_sketch_sums(b.data() + k * m, m, n, sketch, wi.data(), &ek, 0, 3 * m);
      size_t differ = 0;
      for (size_t c = 0; c < s; ++c)
        for (size_t r = 0; r < m; ++r) differ += w[c * 3 * m + k * m + r] != wi[c * m + r];
      EXPECT_EQ(differ, 0u) << "m " << m << ", matrix " << k;
      double ref = 0;
      for (size_t t = 0; t < n; ++t)
        for (size_t r = 0; r < m; ++r) ref += double(b[t * 3 * m + k * m + r]) * b[t * 3 * m + k * m + r];
      EXPECT_NEAR(e[k], ref, 1e-12 * ref) << "m " << m << ", matrix " << k;
      EXPECT_NEAR(ek, ref, 1e-12 * ref);
    }
  }
}

// One staged Y (StagedY) serves several products, as a pass's parts share Q: each gives the bits
// of the call with Y itself, whatever B's width, leading dimension or place, and the staged copy
// outlives Y. B X written into a block of a larger matrix (its leading dimension) gives the bits
// of a plain result, with and without the tiles' padded columns.
TEST(Svd, StagedOperandAndStridedResultGiveTheBitsOfThePlainProducts) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<float> u(-1.f, 1.f);
  const size_t m = 2100, ld = 3 * m + 5;
  std::vector<float> tall(ld * 300);
  for (float& x : tall) x = u(rng);
  for (int l : {5, 17, 40, 48, 100, 130}) {
    auto Y = std::make_unique<Eigen::MatrixXf>(Eigen::Index(m), l);
    for (Eigen::Index i = 0; i < Y->size(); ++i) Y->data()[i] = u(rng);
    const Eigen::MatrixXf Ycopy = *Y;
    const StagedY staged(*Y);
    EXPECT_EQ(staged.rows(), Eigen::Index(m));
    EXPECT_EQ(staged.cols(), l);
    Y.reset();  // the staged copy is its own
    for (auto [off, n, ldb] : {std::tuple<size_t, size_t, size_t>{0, 300, ld}, {7, 123, ld}, {m, 9, ld}, {0, 1, m}}) {
      const float* B = tall.data() + off;
      Eigen::MatrixXf Z1, Z2(Eigen::Index(n), l);
      double e1 = -1, e2 = -1;
      transposed_product(B, m, n, Ycopy, Z1, &e1, ldb);
      transposed_product(B, m, n, staged, Z2, &e2, ldb);
      EXPECT_TRUE(Z1 == Z2) << "l " << l << " n " << n;
      EXPECT_EQ(e1, e2) << "l " << l << " n " << n;
      const Eigen::MatrixXd ref = Eigen::Map<const Eigen::MatrixXf, 0, Eigen::OuterStride<>>(B, Eigen::Index(m), Eigen::Index(n),
                                                                                           Eigen::OuterStride<>(Eigen::Index(ldb)))
                                      .cast<double>()
                                      .transpose() *
                                  Ycopy.cast<double>();
      EXPECT_LT((Z2.cast<double>() - ref).cwiseAbs().maxCoeff(), 4e-7 * double(m)) << "l " << l << " n " << n;
    }
    // B X into columns [3, 3 + l) of a wider matrix with more rows (outer stride m + 11).
    Eigen::MatrixXf X(Eigen::Index(250), l), P1, big = Eigen::MatrixXf::Constant(Eigen::Index(m + 11), l + 6, 9.f);
    for (Eigen::Index i = 0; i < X.size(); ++i) X.data()[i] = u(rng);
    thin_product(tall.data() + 3, m, 250, X, P1, ld);
    thin_product(tall.data() + 3, m, 250, X, Eigen::Ref<Eigen::MatrixXf>(big.block(2, 3, Eigen::Index(m), l)), ld);
    EXPECT_TRUE(big.block(2, 3, Eigen::Index(m), l) == P1) << "B X into a block, l " << l;
    big.block(2, 3, Eigen::Index(m), l).setConstant(9.f);
    EXPECT_EQ((big.array() != 9.f).count(), 0) << "nothing written outside the block, l " << l;
  }
}

// B as rows [7, 7 + m) of a taller matrix (leading dimension 3 m + 5, as color=dfmf's channels
// in place): every product and the column sketch give the bits they give on a contiguous copy.
TEST(Svd, ProductsWithALeadingDimensionGiveTheContiguousBits) {
  std::mt19937_64 rng(6);
  std::uniform_real_distribution<float> u(-1.f, 1.f);
  const size_t m = 41, n = 1100, ld = 3 * m + 5, off = 7;
  std::vector<float> tall(ld * n), flat(m * n);
  for (float& x : tall) x = u(rng);
  for (size_t j = 0; j < n; ++j) std::copy_n(tall.data() + j * ld + off, m, flat.data() + j * m);
  const float* sub = tall.data() + off;
  for (int l : {5, 17, 40, 130}) {
    Eigen::MatrixXf Y(Eigen::Index(m), l), X(Eigen::Index(n), l), Z1, Z2, P1, P2;
    for (Eigen::Index i = 0; i < Y.size(); ++i) Y.data()[i] = u(rng);
    for (Eigen::Index i = 0; i < X.size(); ++i) X.data()[i] = u(rng);
    double e1 = -1, e2 = -1;
    transposed_product(sub, m, n, Y, Z1, &e1, ld);
    transposed_product(flat.data(), m, n, Y, Z2, &e2);
    EXPECT_TRUE(Z1 == Z2) << "B^T Y, l " << l;
    EXPECT_NEAR(e1, e2, 1e-12 * e2) << "energy, l " << l;
    thin_product(sub, m, n, X, P1, ld);
    thin_product(flat.data(), m, n, X, P2);
    EXPECT_TRUE(P1 == P2) << "B X, l " << l;
    // The kernels this CPU's products may not take: the AVX2 B^T Y, the AVX-512 and AVX2 B X tiles.
    if (transposed_product_avx2(sub, m, n, Y, Z1, &e1, ld) && transposed_product_avx2(flat.data(), m, n, Y, Z2, &e2)) {
      EXPECT_TRUE(Z1 == Z2) << "AVX2 B^T Y, l " << l;
      EXPECT_EQ(e1, e2);
    }
    if (thin_product_tiles(sub, m, n, X, P1, ld) && thin_product_tiles(flat.data(), m, n, X, P2)) {
      EXPECT_TRUE(P1 == P2) << "B X tiles, l " << l;
    }
    if (thin_product_avx2(sub, m, n, X, P1, ld) && thin_product_avx2(flat.data(), m, n, X, P2)) {
      EXPECT_TRUE(P1 == P2) << "B X AVX2 tiles, l " << l;
    }
  }
  SvdOptions opt;
  const Sketch sketch = make_column_sketch(n, 12, opt);
  ASSERT_TRUE(sketch.sparse());
  std::vector<float> w1(m * sketch.S.s, 0.0f), w2(w1.size(), 0.0f);
  double e1 = 0, e2 = 0;
  column_sketch_sums(sub, m, n, sketch, w1.data(), &e1, 0, ld);
  column_sketch_sums(flat.data(), m, n, sketch, w2.data(), &e2, 0);
  EXPECT_EQ(w1, w2);
  EXPECT_EQ(e1, e2);
  Eigen::MatrixXf y1(Eigen::Index(m), 12), y2(Eigen::Index(m), 12);
  column_sketch_product(sub, m, n, sketch, y1, &e1, 0, nullptr, ld);
  column_sketch_product(flat.data(), m, n, sketch, y2, &e2);
  EXPECT_TRUE(y1 == y2);
  EXPECT_EQ(e1, e2);
  // The dense start (a Gaussian Pi, B Pi through thin_product) and its energy column by column.
  opt.sparse_sketch = false;
  const Sketch dense = make_column_sketch(n, 12, opt);
  ASSERT_FALSE(dense.sparse());
  column_sketch_product(sub, m, n, dense, y1, &e1, 0, nullptr, ld);
  column_sketch_product(flat.data(), m, n, dense, y2, &e2);
  EXPECT_TRUE(y1 == y2);
  EXPECT_NEAR(e1, e2, 1e-12 * e2);
  EXPECT_NEAR(squared_norm(sub, m, n, ld), e2, 1e-12 * e2);
}

TEST(Svd, LargeGramEigenpairsEqualEigensSolver) {
  // 1100 > 1024: top_eigenpairs asks LAPACK (dsyevd) when built with OpenBLAS; Eigen's solver is
  // the reference. Eigenvalues agree to double round-off relative to the largest; eigenvectors
  // span the same lines (|cos| = 1) where the eigenvalues are well separated.
  const Eigen::Index k = 1100;
  const std::vector<float> b = test_matrix(k, 1300, 40, 3);
  Eigen::Map<const Eigen::MatrixXf> B(b.data(), k, 1300);
  const Eigen::MatrixXd G = B.cast<double>() * B.cast<double>().transpose();
  Eigen::VectorXd lambda;
  Eigen::MatrixXd vecs;
  top_eigenpairs(G, 30, lambda, vecs);
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> ref(G);
  double max_rel = 0, min_cos = 1;
  for (int i = 0; i < 30; ++i) {
    max_rel = std::max(max_rel, std::abs(lambda(i) - ref.eigenvalues()(k - 1 - i)) / ref.eigenvalues()(k - 1));
    min_cos = std::min(min_cos, std::abs(vecs.col(i).dot(ref.eigenvectors().col(k - 1 - i))));
  }
  std::printf("max relative eigenvalue difference %.3g, min |cos| %.12f\n", max_rel, min_cos);
  EXPECT_LT(max_rel, 1e-12);
  EXPECT_GT(min_cos, 1 - 1e-9);
  for (int i = 1; i < 30; ++i) EXPECT_GE(lambda(i - 1), lambda(i));
}

TEST(Svd, ExactPathInDoubleBlocksMatchesTheSpectrumOnBothSides) {
  // B = X diag(d) Y^T with Gaussian X (m x 40), Y (n x 40): its singular values are those of the
  // 40 x 40 core Rx diag(d) Ry^T (X = Qx Rx, Y = Qy Ry), in double. Sizes with several double
  // blocks of B (exact_double_block) on each Gram side, and Grams of 300 and 600 rows: LAPACK's
  // solver (k_exact_lapack_eigen_from). The kept spectrum, U's orthonormality and the error of
  // U SxV^T match the core's to float rounding.
  for (auto [m, n] : {std::pair<size_t, size_t>{16000, 600}, {300, 9000}}) {
    const Eigen::Index k = Eigen::Index(std::min(m, n)), len = Eigen::Index(std::max(m, n));
    ASSERT_GE(k, k_exact_lapack_eigen_from);
    ASSERT_GT(len, 2 * exact_double_block(k)) << "at least three blocks";
    std::mt19937_64 rng(11);
    std::normal_distribution<double> g(0.0, 1.0);
    Eigen::MatrixXd X(Eigen::Index(m), 40), Y(Eigen::Index(n), 40);
    for (Eigen::Index i = 0; i < X.size(); ++i) X.data()[i] = g(rng);
    for (Eigen::Index i = 0; i < Y.size(); ++i) Y.data()[i] = g(rng);
    Eigen::VectorXd d(40);
    for (int i = 0; i < 40; ++i) d(i) = std::pow(0.85, i);
    const Eigen::MatrixXf Bf = (X * d.asDiagonal() * Y.transpose()).cast<float>();
    const Eigen::MatrixXd Rx = Eigen::HouseholderQR<Eigen::MatrixXd>(X).matrixQR().topRows(40).triangularView<Eigen::Upper>();
    const Eigen::MatrixXd Ry = Eigen::HouseholderQR<Eigen::MatrixXd>(Y).matrixQR().topRows(40).triangularView<Eigen::Upper>();
    const Eigen::VectorXd s = Eigen::JacobiSVD<Eigen::MatrixXd>(Rx * d.asDiagonal() * Ry.transpose()).singularValues();
    SvdOptions o;
    o.max_rank = 12;
    o.method = SvdMethod::exact;
    auto r = truncated_svd(Bf.data(), m, n, o);
    ASSERT_TRUE(r.ok()) << r.status().message();
    EXPECT_EQ(r->method, "exact");
    ASSERT_EQ(r->S.size(), 12);
    for (int i = 0; i < 12; ++i) EXPECT_NEAR(r->S(i) / s(i), 1.0, 1e-5) << m << " x " << n << ", sigma " << i;
    const Eigen::MatrixXf UtU = r->U.transpose() * r->U;
    EXPECT_LT((UtU - Eigen::MatrixXf::Identity(12, 12)).cwiseAbs().maxCoeff(), 1e-4);
    const double tail = s.tail(28).squaredNorm(), err = (Bf - r->U * r->SxV.transpose()).cast<double>().squaredNorm();
    EXPECT_NEAR(err / tail, 1.0, 1e-3) << m << " x " << n;
  }
}

TEST(Svd, ExactThresholdTakesLapackForModerateGrams) {
  // The exact path's solver from k_exact_lapack_eigen_from rows on: dsyevd against Eigen's
  // solver on a 200 x 200 Gram matrix, as LargeGramEigenpairsEqualEigensSolver at 1100.
  const Eigen::Index k = 200;
  const std::vector<float> b = test_matrix(size_t(k), 500, 30, 9);
  Eigen::Map<const Eigen::MatrixXf> B(b.data(), k, 500);
  const Eigen::MatrixXd G = B.cast<double>() * B.cast<double>().transpose();
  Eigen::VectorXd lambda, lambda_eigen;
  Eigen::MatrixXd vecs, vecs_eigen;
  top_eigenpairs(G, 20, lambda, vecs, k_exact_lapack_eigen_from);
  top_eigenpairs(G, 20, lambda_eigen, vecs_eigen);  // the default threshold: Eigen's solver at 200
  for (int i = 0; i < 20; ++i) {
    EXPECT_NEAR(lambda(i), lambda_eigen(i), 1e-12 * lambda_eigen(0)) << i;
    EXPECT_NEAR(std::abs(vecs.col(i).dot(vecs_eigen.col(i))), 1.0, 1e-9) << i;
  }
}

TEST(Svd, SymmetricEigenGivesEigensSolverAscendingOnEitherSide) {
  // symmetric_eigen, the Krylov iterations' stopping tests and restarts: below its threshold
  // Eigen's own solver (the same bits), from it on LAPACK (values, and vectors when asked),
  // ascending as Eigen's. A 200 x 200 Gram matrix of rank 30 (170 eigenvalues at round-off).
  const Eigen::Index k = 200;
  const std::vector<float> b = test_matrix(size_t(k), 500, 30, 5);
  Eigen::Map<const Eigen::MatrixXf> B(b.data(), k, 500);
  const Eigen::MatrixXd G = B.cast<double>() * B.cast<double>().transpose();
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> ref(G);
  Eigen::VectorXd below, values, with_vecs;
  Eigen::MatrixXd vecs;
  symmetric_eigen(G, below, nullptr, k + 1);
  EXPECT_EQ(std::memcmp(below.data(), ref.eigenvalues().data(), sizeof(double) * size_t(k)), 0) << "Eigen's bits below the threshold";
  symmetric_eigen(G, values, nullptr, k);
  symmetric_eigen(G, with_vecs, &vecs, k);
  ASSERT_EQ(values.size(), k);
  ASSERT_EQ(vecs.rows(), k);
  ASSERT_EQ(vecs.cols(), k);
  const double top = ref.eigenvalues()(k - 1);
  for (Eigen::Index i = 0; i < k; ++i) {
    EXPECT_NEAR(values(i), ref.eigenvalues()(i), 1e-12 * top) << i;
    EXPECT_NEAR(with_vecs(i), ref.eigenvalues()(i), 1e-12 * top) << i;
    if (i > 0) {
      EXPECT_LE(values(i - 1), values(i)) << "ascending";
    }
  }
  // The 30 leading vectors: G v = lambda v to round-off (the rest span a numerically null space).
  for (Eigen::Index i = k - 30; i < k; ++i)
    EXPECT_LT((G * vecs.col(i) - with_vecs(i) * vecs.col(i)).norm(), 1e-10 * top) << i;
}

TEST(Svd, AutomaticPathIsExactForLargeRanksOfAModerateSide) {
  const size_t m = 1300, n = 1100;  // small side 1100: randomized at rank 32, exact from rank 122
  const std::vector<float> b = test_matrix(m, n, 60, 4);
  SvdOptions o;
  o.max_rank = 32;
  auto low = truncated_svd(b.data(), m, n, o);
  ASSERT_TRUE(low.ok()) << low.status().message();
  EXPECT_EQ(low->method, "randomized");
  o.max_rank = 200;  // (200 + 16) x 8 >= 1100
  auto high = truncated_svd(b.data(), m, n, o);
  ASSERT_TRUE(high.ok()) << high.status().message();
  EXPECT_EQ(high->method, "exact");
  // Exact: the kept energy is the Eckart-Young optimum, the sum of the top 200 eigenvalues.
  EXPECT_NEAR(high->rel_error_estimate(), std::sqrt(std::max(0.0, high->total_energy - high->kept_energy) / high->total_energy), 1e-12);
  EXPECT_LE(high->rel_error_estimate(), low->rel_error_estimate());
}

}  // namespace
}  // namespace btfc
