// The block Krylov SVDs' building blocks (svd.h: the column sketch, gram_columns,
// orthonormalize_against, gaussian_matrix), shared by the in-core path (svd.cpp) and the streamed
// and MPI passes (codecs/fmf/ooc_svd.cpp); apart from svd.cpp so that each reads in one sitting.
#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <optional>
#include <random>
#include <vector>

#include "core/blas_env.h"
#include "core/btf.h"
#include "core/memory.h"
#include "core/sparse_sketch.h"
#include "core/svd.h"
#include "core/thin_product.h"

namespace btfc {

using Eigen::Index;
using Eigen::MatrixXd;
using Eigen::MatrixXf;

// Gaussian test matrix (rows x cols) from a seeded engine: Box-Muller on raw 64-bit draws so
// the numbers do not depend on the standard library's distribution implementation.
MatrixXf gaussian_matrix(Index rows, Index cols, uint64_t seed) {
  MatrixXf Om(rows, cols);
  std::mt19937_64 rng(seed);
  const double k_two_pi = 6.283185307179586;
  for (Index i = 0; i < Om.size(); i += 2) {
    double u1 = (double(rng() >> 11) + 0.5) * (1.0 / 9007199254740992.0);
    double u2 = (double(rng() >> 11) + 0.5) * (1.0 / 9007199254740992.0);
    double rad = std::sqrt(-2.0 * std::log(u1));
    Om.data()[i] = float(rad * std::cos(k_two_pi * u2));
    if (i + 1 < Om.size()) Om.data()[i + 1] = float(rad * std::sin(k_two_pi * u2));
  }
  return Om;
}

namespace {

// One Cholesky QR round: X := X R^-1 with R^T R = X^T X (a BLAS-3 product and a triangular
// solve, in double). False, X unchanged, when the Gram matrix is not numerically positive
// definite or R's diagonal spans more than 1e5 (cond(X)^2 u would then lose orthogonality
// beyond what a second round restores): the caller falls back to Householder.
bool cholesky_qr_round(Eigen::Ref<MatrixXd> X) {
  const Index l = X.cols();
  MatrixXd G = MatrixXd::Zero(l, l);
  G.selfadjointView<Eigen::Lower>().rankUpdate(X.transpose());
  Eigen::LLT<MatrixXd> llt(G);
  if (llt.info() != Eigen::Success) return false;
  const Eigen::VectorXd d = llt.matrixLLT().diagonal();
  if (!(d.minCoeff() > 1e-5 * d.maxCoeff())) return false;
  llt.matrixU().solveInPlace<Eigen::OnTheRight>(X);
  return true;
}

}  // namespace

// The sketch's buckets: s = 4 l rounded up to a multiple of 128, at least 256 (then as good a
// start as a Gaussian one, sparse_sketch.h), when B has at least 4 s columns (fewer: the dense
// pass is cheap there and the sketch hardly smaller than B) and s <= 1024 (l <= 256). One
// nonzero per column (CountSketch): sparse_sign_columns reads a texel's column once per layer,
// so a second layer would double the pass (0.73 s instead of 0.46 s at UBO2003 size). On the
// rows, over six seeds, 1, 2 and 4 nonzeros and the dense Gaussian start gave the same mean
// error within the seed-to-seed spread (docs/benchmarks.md).
namespace {
size_t sketch_buckets(Index l) { return (std::max<size_t>(4 * size_t(l), 256) + 127) / 128 * 128; }
bool sketch_sparse(size_t n, size_t s) { return s <= 1024 && n >= 4 * s && n < (size_t(1) << 30); }
// Rows of B per block of column_sketch_product: its scratch holds rows x s floats, at most 16 MiB
// and at most n l floats (what a dense Pi would take; the out-of-core plans count that), 16 rows
// at least. Blocks of 4096 rows or more let sparse_sign_columns stream B in texel order, by
// chunks of 2048 rows: a multiple of 4096 rows keeps two threads evenly busy (8192 rows at the
// UBO2003 size, n = 65536, l = 40, s = 256: 0.30-0.32 s for the pass against 0.35-0.36 s with
// 10240 and 0.46 s in 2048-row blocks in bucket order, bench_products).
size_t sketch_rows(size_t m, size_t n, Index l, size_t s) {
  const size_t floats = std::min<size_t>(size_t(1) << 22, n * size_t(l)), rows = std::max<size_t>(floats / s, 16);
  return std::min(m, rows >= 4096 ? rows / 4096 * 4096 : rows);
}
}  // namespace

size_t column_sketch_bytes(size_t m, size_t n, Index l) {
  const size_t s = sketch_buckets(l);
  return sketch_sparse(n, s) ? sketch_rows(m, n, l, s) * s * sizeof(float) : 0;
}

Sketch make_column_sketch(size_t n, Index l, const SvdOptions& opt) {
  Sketch r;
  const size_t s = sketch_buckets(l);
  if (opt.sparse_sketch && sketch_sparse(n, s)) {
    r.S = make_sparse_sign(n, s, opt.seed, 1);
    r.G = gaussian_matrix(Index(r.S.s), l, opt.seed);
  } else {
    r.G = gaussian_matrix(Index(n), l, opt.seed);
  }
  return r;
}

namespace {
// Y = W G (W h x s column-major, Y h x l) on the threads in pieces of k_piece rows (one BLAS
// thread each, as the passes' products; the pieces do not depend on the thread count, nor do the
// bits): on one thread it left the other idle, ~1 ms per block of 8192 rows, three blocks per
// chunk of the streamed SVD (its first pass 0.44-0.45 -> 0.42-0.44 s at UBO2003 size, 20 chunks,
// rank 32, old and new binaries alternating; it now adds its chunks' sums first and multiplies
// once: column_sketch_sums).
void sketch_times_gaussian(const float* w, size_t h, const Sketch& sketch, Eigen::Ref<MatrixXf> Y, size_t ldw = 0) {
  constexpr size_t k_piece = 512;
  const Eigen::Map<const MatrixXf, 0, Eigen::OuterStride<>> W(w, Index(h), Index(sketch.S.s), Eigen::OuterStride<>(Index(ldw ? ldw : h)));
  const int pieces = int((h + k_piece - 1) / k_piece);
  const SingleThreadedBlas one_blas_thread(pieces > 1);
#pragma omp parallel for schedule(dynamic, 1) if (pieces > 1)
  for (int k = 0; k < pieces; ++k) {
    const Index r0 = Index(k) * Index(k_piece), r1 = std::min(Index(h), r0 + Index(k_piece));
    Y.middleRows(r0, r1 - r0).noalias() = W.middleRows(r0, r1 - r0) * sketch.G;
  }
}
}  // namespace

// Sparse: W = B S in one pass at memory speed (and ||B||_F^2), then W G; dense: B G.
void column_sketch_product(const float* B, size_t m, size_t n, const Sketch& sketch, Eigen::Ref<MatrixXf> Y, double* energy, size_t first,
                           std::vector<float>* scratch, size_t ldb) {
  if (ldb == 0) ldb = m;
  if (!sketch.sparse()) {
    thin_product(B, m, n, sketch.G.middleRows(Index(first), Index(n)), Y, ldb);
    if (energy) *energy = squared_norm(B, m, n, ldb);
    return;
  }
  // By blocks of rows, so the sketch W = B S (m x s) is never whole: a reused rows x s buffer.
  const size_t s = sketch.S.s, rows = sketch_rows(m, sketch.S.m, sketch.G.cols(), s);
  // Without the caller's scratch, huge pages left unwritten: sparse_sign_columns zeroes each
  // part of W on the thread that sums into it (a vector's zero fill was 8 MB of page faults on
  // the main thread at UBO2003 size).
  std::optional<PageBuffer<float>> own;
  float* w = nullptr;
  if (scratch) {
    scratch->resize(rows * s);
    w = scratch->data();
  } else {
    own.emplace(rows * s);
    w = own->data();
  }
  if (energy) *energy = 0;
  for (size_t i0 = 0; i0 < m; i0 += rows) {
    const size_t h = std::min(rows, m - i0);
    double e = 0;
    sparse_sign_columns(B + i0, ldb, h, n, sketch.S, w, energy ? &e : nullptr, first);
    if (energy) *energy += e;  // in block order: independent of the thread count
    sketch_times_gaussian(w, h, sketch, Y.middleRows(Index(i0), Index(h)));
  }
}

void column_sketch_sums(const float* B, size_t m, size_t n, const Sketch& sketch, float* W, double* energy, size_t first, size_t ldb,
                        size_t segment) {
  const size_t segments = segment ? (m + segment - 1) / segment : 1;  // 0 for m = 0 rows in segments
  std::vector<double> e(std::max<size_t>(1, segments), 0.0);          // sparse_sign_columns counts one then
  sparse_sign_columns(B, ldb ? ldb : m, m, n, sketch.S, W, energy ? e.data() : nullptr, first, true, segment);
  if (energy)
    for (size_t k = 0; k < segments; ++k) energy[k] += e[k];
}

void column_sketch_finish(const float* W, size_t m, const Sketch& sketch, Eigen::Ref<MatrixXf> Y, size_t ldw) {
  sketch_times_gaussian(W, m, sketch, Y, ldw);
}

size_t column_sketch_sums_bytes(size_t m, size_t n, Index l) {
  const size_t s = sketch_buckets(l);
  return sketch_sparse(n, s) ? m * s * sizeof(float) : 0;
}

MatrixXd gram_columns(const Eigen::Ref<const MatrixXf>& Wt, Index from) {
  // Blocks of rows of at most ~4 MB in double (4096 rows up to w = 128), in at most 16 groups on
  // the OpenMP threads (BLAS has one where the SVDs call this), each group summing its blocks in
  // order, the groups summed in order after: the same bits at any thread count. At least four
  // blocks from 1024 rows: the streamed SVDs call this per chunk (~3400 texels at UBO2003 size),
  // where one block left one core idle for a tenth of the last pass (docs/benchmarks.md).
  const Index n = Wt.rows(), w = Wt.cols(), add = w - from;
  const Index rows_per = std::clamp<Index>(std::min<Index>((Index(1) << 19) / std::max<Index>(1, w), (n + 3) / 4), 256, 4096);
  const Index blocks_of_rows = (n + rows_per - 1) / rows_per, groups = std::min<Index>(blocks_of_rows, 16);
  std::vector<MatrixXd> parts(static_cast<size_t>(groups));
#pragma omp parallel for schedule(static) if (groups > 1)
  for (Index g = 0; g < groups; ++g) {
    MatrixXd rows, sum = MatrixXd::Zero(w, add);
    for (Index b = blocks_of_rows * g / groups; b < blocks_of_rows * (g + 1) / groups; ++b) {
      const Index i = b * rows_per;
      rows = Wt.middleRows(i, std::min<Index>(rows_per, n - i)).cast<double>();
      sum.noalias() += rows.transpose() * rows.rightCols(add);
    }
    parts[size_t(g)] = std::move(sum);
  }
  MatrixXd part = MatrixXd::Zero(w, add);
  for (const MatrixXd& p : parts) part += p;
  return part;
}

// X := an orthonormal basis of X's columns orthogonal to P's: block classical Gram-Schmidt and
// QR, twice ("twice is enough"; the second round after normalising, so a block that is noise
// after the projection, as when the Krylov space has exhausted B's range, is still made
// orthogonal to P to round-off). The projections are (rows of X) x (used) x l double GEMMs. The QR is
// Cholesky QR (CholeskyQR2 over the two rounds: 10-20x faster than Householder for 65536 x 48,
// whose unblocked reflectors were a third of a Krylov run's time), Householder where a round's
// Gram matrix is too ill-conditioned (rank-deficient or exhausted blocks, zero data).
//
// A column that lies in span(P) to double precision (an exhausted range: B B^T Q of a constant
// matrix is exactly constant in float, like a column already in P) leaves a residual of pure
// rounding after a projection, which can itself lie along P; normalised, it would enter the
// basis as a second copy of a direction already there (the Ritz values then count that
// direction's energy once per copy). Such columns (residual below 1e-9 of the column) are
// replaced by pseudo-random ones before the QR: a random direction has a component outside
// span(P) that the rounds keep; it carries no energy of B and so changes no kept component.
// After the second round X is checked (orthonormal, orthogonal to P to 1e-10). It can fail where
// float rounding leaves X rank-deficient after the projection (a constant matrix's exhausted
// blocks: B B^T Q is constant but for the rounding of the float product): the Householder
// fallback then completes X with arbitrary columns, possibly inside span(P), and X is taken
// instead from the Householder QR of [P X] (orthogonal to P by construction).
void orthonormalize_against(const Eigen::Ref<const MatrixXd>& P, Index used, Eigen::Ref<MatrixXd> X) {
  auto project = [&] {
    if (used == 0) return;
    const auto Pu = P.leftCols(used);
    MatrixXd C = Pu.transpose() * X;
    X.noalias() -= Pu * C;
  };
  auto qr = [&] {
    if (cholesky_qr_round(X)) return;
    Eigen::HouseholderQR<MatrixXd> h(X);
    X = h.householderQ() * MatrixXd::Identity(X.rows(), X.cols());
  };
  const Index l = X.cols();
  if (used > 0) {
    const Eigen::VectorXd before = X.colwise().norm();
    project();
    for (Index c = 0; c < l; ++c) {
      if (X.col(c).norm() > 1e-9 * before(c) && before(c) > 0) continue;
      std::mt19937_64 rng(0x9E3779B97F4A7C15ull ^ uint64_t(used + c));
      for (Index i = 0; i < X.rows(); ++i) X(i, c) = double(rng() >> 11) * (1.0 / 9007199254740992.0) - 0.5;
    }
  }
  qr();
  project();
  qr();
  if (used == 0 || used + l > X.rows()) return;
  // The check, and the fallback: Householder's Q of [P X], whose columns after P's are
  // orthonormal and orthogonal to span(P) whatever X holds.
  const double off_p = (P.leftCols(used).transpose() * X).cwiseAbs().maxCoeff();
  const double off_x = (X.transpose() * X - MatrixXd::Identity(l, l)).cwiseAbs().maxCoeff();
  if (off_p <= 1e-10 && off_x <= 1e-10) return;
  MatrixXd A(X.rows(), used + l);
  A << P.leftCols(used), X;
  Eigen::HouseholderQR<MatrixXd> h(A);
  X = (h.householderQ() * MatrixXd::Identity(A.rows(), A.cols())).rightCols(l);
}

}  // namespace btfc
