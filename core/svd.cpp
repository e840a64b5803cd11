// Truncated SVD for fmf; see svd.h for the contract and the choice of paths.
#include "core/svd.h"

#include "core/blas_env.h"
#include "core/btf.h"
#include "core/memory.h"
#include "core/sparse_sketch.h"
#include "core/thin_product.h"

#include <Eigen/Dense>
#include <omp.h>
#include <algorithm>
#include <climits>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <list>
#include <memory>
#include <mutex>
#include <optional>
#include <random>
#include <vector>

#ifdef BTFC_HAVE_OPENBLAS
// LAPACK's symmetric divide-and-conquer eigensolver, in OpenBLAS (Fortran: the trailing hidden
// lengths of the two character arguments are passed, as gfortran expects).
extern "C" void dsyevd_(const char* jobz, const char* uplo, const int* n, double* a, const int* lda, double* w, double* work,
                        const int* lwork, int* iwork, const int* liwork, int* info, size_t jobz_len, size_t uplo_len);
#endif

namespace btfc {

using Eigen::Index;
using Eigen::MatrixXd;
using Eigen::MatrixXf;
using ConstMapF = Eigen::Map<const MatrixXf>;

double SvdResult::rel_error_estimate() const {
  if (total_energy <= 0) return 0;
  return std::sqrt(std::max(0.0, total_energy - kept_energy) / total_energy);
}

namespace {

constexpr double k_rel_sigma_floor = 1e-6;  // float data: smaller singular values are noise

double frobenius2(ConstMapF& B) { return squared_norm(B.data(), size_t(B.size())); }

// The exact path's projection (exact_svd) goes by panels of this many columns of E, every panel a
// product of the same shape (the last one's missing eigenvectors zero): a column's bits then do
// not depend on how many columns were asked for, so panels projected for one rank serve every
// smaller one with the bits that rank gets alone (ExactSvdReuse keeps them).
constexpr Index k_projection_panel = 32;

// ExactSvdReuse's store: the eigendecompositions of the last few Gram matrices, by fingerprint,
// and the panels of their projection computed so far (float, k_projection_panel columns each).
struct GramEigen {
  uint64_t fingerprint = 0;
  Index m = 0, n = 0;
  Eigen::VectorXd lambda;
  MatrixXd E;
  MatrixXfR projected;  // rows_small: SxV = B^T E (n rows); else U = B E / sigma (m rows)
};
std::mutex g_reuse_mutex;
int g_reuse_scopes = 0;
size_t g_reuses = 0, g_projected_columns = 0;
std::list<GramEigen> g_reuse;  // most recent first
constexpr size_t k_reuse_entries = 3;  // dfmf factorizes three channel matrices per encode
// The store's entry for a matrix of fingerprint fp and shape m x n, or end(); g_reuse_mutex held.
std::list<GramEigen>::iterator find_gram(uint64_t fp, Index m, Index n) {
  return std::find_if(g_reuse.begin(), g_reuse.end(), [&](const GramEigen& e) { return e.fingerprint == fp && e.m == m && e.n == n; });
}

// RandomizedSvdReuse's store: one randomized factorization, the largest computed in the scope.
struct KeptRandomized {
  uint64_t fingerprint = 0;
  Index m = 0, n = 0;
  int oversample = 0, power_iters = 0, scheme = 0;
  uint64_t seed = 0;
  bool sparse = false;
  int rank = 0;  // the max_rank it was computed for
  SvdResult r;
};
int g_randomized_scopes = 0, g_randomized_rank = 0;
size_t g_randomized_computed = 0, g_randomized_served = 0;
std::unique_ptr<KeptRandomized> g_kept_randomized;
// RandomizedSvdReuse::serve_set's store: one set of factorizations with the ranks they were
// computed for.
struct KeptSet {
  uint64_t key = 0;
  std::vector<int> ranks;
  RandomizedSvdReuse::Set set;
};
std::unique_ptr<KeptSet> g_kept_set;

// All eigenpairs, sorted by descending eigenvalue (the power scheme's small Rayleigh-Ritz step).
void sorted_eigen(const MatrixXd& G, Eigen::VectorXd& lambda, MatrixXd& vecs) { top_eigenpairs(G, G.rows(), lambda, vecs); }

// A 64-bit fingerprint of every value (as bits), in parallel blocks: ~0.05 s for 300 MB.
uint64_t fingerprint(ConstMapF& B) {
  const size_t total = size_t(B.size()), block = size_t(1) << 20;
  const int64_t blocks = int64_t((total + block - 1) / block);
  uint64_t h = 0x9E3779B97F4A7C15ull ^ total;
#pragma omp parallel for reduction(^ : h) schedule(static)
  for (int64_t b = 0; b < blocks; ++b) {
    const float* p = B.data() + size_t(b) * block;
    const size_t len = std::min(block, total - size_t(b) * block);
    uint64_t x = 0xD6E8FEB86659FD93ull * uint64_t(b + 1);
    for (size_t i = 0; i < len; ++i) {
      uint32_t bits;
      std::memcpy(&bits, p + i, 4);
      x = (x ^ bits) * 0x100000001B3ull;
      x ^= x >> 29;
    }
    h ^= x * (0xA24BAED4963EE407ull + 2 * uint64_t(b));
  }
  return h;
}

// The eigendecomposition of the smaller Gram matrix (B B^T when rows_small, else B^T B), in
// double, eigenvalues descending. Either Gram is summed by symmetric rank updates (BLAS dsyrk) of
// double blocks of B: column blocks for B B^T, row blocks for B^T B (dsyrk on the transpose).
void gram_eigen(ConstMapF& B, bool rows_small, const SvdOptions& opt, Eigen::VectorXd& lambda, MatrixXd& E) {
  const Index m = B.rows(), n = B.cols(), k = rows_small ? m : n, len = rows_small ? n : m;
  MatrixXd G = MatrixXd::Zero(k, k);
  const Index block = exact_double_block(k);
  // One step per Gram block, one for the eigendecomposition, one for the projection.
  if (opt.progress) opt.progress->start("fmf exact SVD", uint64_t((len + block - 1) / block) + 2);
  MatrixXd Bd;
  for (Index j0 = 0; j0 < len; j0 += block) {
    const Index nb = std::min(block, len - j0);
    if (rows_small) {
      Bd = B.middleCols(j0, nb).cast<double>();
      G.selfadjointView<Eigen::Lower>().rankUpdate(Bd);
    } else {
      Bd = B.middleRows(j0, nb).cast<double>();  // copied column by column: no strided transpose
      G.selfadjointView<Eigen::Lower>().rankUpdate(Bd.transpose());
    }
    if (opt.progress) opt.progress->advance();
  }
  G.triangularView<Eigen::StrictlyUpper>() = G.transpose();
  top_eigenpairs(G, k, lambda, E, k_exact_lapack_eigen_from);
  if (opt.progress) opt.progress->advance();
}

// Appends to P (rows x a multiple of k_projection_panel) the panels of B's projection on E's
// columns that bring it to at least `cols` columns: rows_small, P = B^T E (n rows); else P = B E
// diag(1 / sigma) (m rows; 0 where sigma is 0: all-zero input leaves U zero), sigma = sqrt(lambda).
// In double blocks of B as the Gram (BLAS dgemm; a product with B's cast expression ran Eigen's own
// unblocked kernel), one dgemm of one shape per block and panel.
void project_panels(ConstMapF& B, bool rows_small, const Eigen::VectorXd& lambda, const MatrixXd& E, Index cols, MatrixXfR& P) {
  const Index have = P.cols(), want = (cols + k_projection_panel - 1) / k_projection_panel * k_projection_panel;
  if (want <= have) return;
  const Index rows = rows_small ? B.cols() : B.rows(), len = rows_small ? B.rows() : B.cols();
  // The new panels' eigenvectors (and 1 / sigma), zero past E's columns.
  MatrixXd V = MatrixXd::Zero(len, want - have);
  Eigen::VectorXd inv = Eigen::VectorXd::Zero(want - have);
  for (Index c = have; c < std::min(want, E.cols()); ++c) {
    V.col(c - have) = E.col(c);
    const double sigma = std::sqrt(lambda(c));
    inv(c - have) = sigma > 0 ? 1.0 / sigma : 0.0;
  }
  MatrixXfR grown(rows, want);
  if (have > 0) grown.leftCols(have) = P;  // (P is 0 x 0 before the first panel)
  const Index block = exact_double_block(len);
  MatrixXd Bd, panel;
  for (Index i0 = 0; i0 < rows; i0 += block) {
    const Index nb = std::min(block, rows - i0);
    if (rows_small)
      Bd = B.middleCols(i0, nb).cast<double>();
    else
      Bd = B.middleRows(i0, nb).cast<double>();  // copied column by column: no strided transpose
    for (Index c0 = 0; c0 < want - have; c0 += k_projection_panel) {
      const auto Vc = V.middleCols(c0, k_projection_panel);
      if (rows_small) {
        panel.noalias() = Bd.transpose() * Vc;
      } else {
        panel.noalias() = Bd * Vc;
        panel *= inv.segment(c0, k_projection_panel).asDiagonal();
      }
      grown.block(i0, have + c0, nb, k_projection_panel) = panel.cast<float>();
    }
  }
  P = std::move(grown);
  std::lock_guard<std::mutex> lock(g_reuse_mutex);
  g_projected_columns += size_t(want - have);
}

// known_fp: B's fingerprint when the caller has taken it already (0: not taken).
Result<SvdResult> exact_svd(ConstMapF& B, const SvdOptions& opt, uint64_t known_fp = 0) {
  const Index m = B.rows(), n = B.cols();
  const bool rows_small = m <= n;
  Eigen::VectorXd lambda;
  MatrixXd E;
  MatrixXfR projected;
  // The lock is held to look up and to store, not while computing: codecs factorize several
  // matrices in parallel.
  bool reuse = false, reused = false;
  uint64_t fp = 0;
  {
    std::lock_guard<std::mutex> lock(g_reuse_mutex);
    reuse = g_reuse_scopes > 0;
  }
  if (reuse) {
    fp = known_fp ? known_fp : fingerprint(B);
    std::lock_guard<std::mutex> lock(g_reuse_mutex);
    auto it = find_gram(fp, m, n);
    if (it != g_reuse.end()) {
      lambda = it->lambda;
      E = it->E;
      projected = it->projected;
      g_reuse.splice(g_reuse.begin(), g_reuse, it);
      ++g_reuses;
      reused = true;
    }
  }
  if (reused) {
    if (opt.progress) opt.progress->start("fmf exact SVD (reused)", 1);
  } else {
    gram_eigen(B, rows_small, opt, lambda, E);
  }
  SvdResult r;
  r.method = "exact";
  r.requested_rank = opt.max_rank;
  r.total_energy = lambda.sum();  // trace(G) = ||B||_F^2, in double
  const int rank = choose_rank(lambda, r.total_energy, opt, r.data_rank_limit, r.target_reached);
  r.S = lambda.head(rank).cwiseSqrt();
  r.kept_energy = lambda.head(rank).sum();
  const Index had = projected.cols();
  project_panels(B, rows_small, lambda, E, rank, projected);
  if (rows_small) {
    // U = top eigenvectors of B B^T; SxV = B^T U is the projection (no division by sigma).
    r.U = E.leftCols(rank).cast<float>();
    r.SxV = projected.leftCols(rank);
  } else {
    // V = top eigenvectors of B^T B; U = B V / sigma; SxV = V sigma.
    r.U = projected.leftCols(rank);
    r.SxV = (E.leftCols(rank) * r.S.asDiagonal()).cast<float>();
  }
  if (reuse && (!reused || projected.cols() > had)) {
    std::lock_guard<std::mutex> lock(g_reuse_mutex);
    if (g_reuse_scopes > 0) {
      auto it = find_gram(fp, m, n);
      if (it == g_reuse.end()) {
        g_reuse.push_front(GramEigen{fp, m, n, std::move(lambda), std::move(E), std::move(projected)});
        if (g_reuse.size() > k_reuse_entries) g_reuse.pop_back();
      } else if (projected.cols() > it->projected.cols()) {
        it->projected = std::move(projected);
      }
    }
  }
  if (opt.progress) opt.progress->finish();
  return r;
}

// The passes' products (core/thin_product.h), on the mapped data.
template <class Out>
void product_bt(ConstMapF& B, const ConstRefF& Y, Out&& Z, double* energy = nullptr) {
  transposed_product(B.data(), size_t(B.rows()), size_t(B.cols()), Y, std::forward<Out>(Z), energy);
}
template <class Out>
void product_b(ConstMapF& B, const ConstRefF& X, Out&& Y) {
  thin_product(B.data(), size_t(B.rows()), size_t(B.cols()), X, std::forward<Out>(Y));
}

}  // namespace

namespace {

// Orthonormal basis of the columns of Y (in double for stability).
MatrixXf orthonormalize(const MatrixXf& Y) {
  MatrixXd Yd = Y.cast<double>();
  orthonormalize_against(MatrixXd(), 0, Yd);
  return Yd.cast<float>();
}

Status non_finite_input() { return corrupt_data("SVD input holds a non-finite value (NaN or infinity)"); }

Result<SvdResult> power_svd(ConstMapF& B, const SvdOptions& opt) {
  const Index m = B.rows(), n = B.cols();
  const Index l = std::min<Index>(std::min(m, n), Index(opt.max_rank) + opt.oversample);
  if (opt.progress) opt.progress->start("fmf randomized SVD", uint64_t(2 * opt.power_iters + 3));
  auto step = [&] { if (opt.progress) opt.progress->advance(); };

  MatrixXf Omega = gaussian_matrix(n, l, opt.seed);
  SvdResult r;
  r.method = "randomized";
  r.requested_rank = opt.max_rank;
  r.total_energy = frobenius2(B);
  if (!std::isfinite(r.total_energy)) return non_finite_input();
  step();

  MatrixXf Y;
  product_b(B, Omega, Y);  // m x l
  Omega.resize(0, 0);
  step();
  MatrixXf Q = orthonormalize(Y);
  MatrixXf Z;
  for (int it = 0; it < opt.power_iters; ++it) {
    product_bt(B, Q, Z);  // n x l
    step();
    Z = orthonormalize(Z);
    product_b(B, Z, Y);
    step();
    Q = orthonormalize(Y);
  }
  // W^T = B^T Q (n x l); the small SVD comes from the l x l Gram matrix of W^T, in double.
  MatrixXf Wt;
  product_bt(B, Q, Wt);
  step();
  MatrixXd G = (Wt.transpose() * Wt).cast<double>();
  Eigen::VectorXd lambda;
  MatrixXd E;
  sorted_eigen(G, lambda, E);
  const int rank = choose_rank(lambda, r.total_energy, opt, r.data_rank_limit, r.target_reached);
  r.S = lambda.head(rank).cwiseSqrt();
  r.kept_energy = lambda.head(rank).sum();
  MatrixXf Ek = E.leftCols(rank).cast<float>();
  r.U = Q * Ek;
  r.SxV = Wt * Ek;
  if (opt.progress) opt.progress->finish();
  return r;
}

}  // namespace

namespace {

// Randomized block Krylov SVD (Musco and Musco 2015, Algorithm 2; the Ritz step of Halko et al.
// 2011, section 4.3) on the rows side: blocks Q_1 = orth(B Pi), Q_{i+1} = orth(B B^T Q_i) (Pi =
// S G, a sparse sign sketch of B's columns and a Gaussian, for wide enough B:
// make_column_sketch), every block kept and made orthogonal to the earlier ones, so Q = [Q_1 ..
// Q_k] is an orthonormal basis of the Krylov space K_k(B B^T, B Pi). Block i's second pass,
// W_i^T = B^T Q_i, serves twice: it is the next block's start (Q_{i+1} from B W_i^T) and block
// i's part of W^T = B^T Q, the projection the Ritz step needs (B ~ Q Q^T B = Q W). So k blocks
// cost the sketch (a read of B), k passes B^T Q_i (btfc's kernels, core/thin_product.h) and
// k - 1 passes B X: one B X fewer than the same Krylov space built on the texel side, whose Ritz
// step needs B P of its last block (B X is OpenBLAS's product on most CPUs, slower than btfc's
// B^T Y: docs/benchmarks.md). The Ritz step is the SVD of W = Q^T B from the eigenpairs of
// W W^T = E L E^T (w x w, double; mostly computed already for the stopping test): U = Q E,
// orthonormal at any conditioning, and SxV = W^T E = B^T U, the exact projection. The error of
// Q Q^T B truncated to rank C is ||B||^2 - sum of the C largest eigenvalues. Stops early, after
// at least two blocks, when a block improved that error by less than k_krylov_stop of itself
// (the remaining gap to the optimum then is a fraction of that), and before the basis would
// exceed the small side of B (k_krylov_stop, svd.h).
//
// With q >= 2 (three blocks or more: later_krylov_width, svd.h) only the first block is l = C
// + oversample wide. Block 2 starts from B B^T Q_1 E, E the top lk = C eigenvectors of W_1 W_1^T
// (Q_1 E: the first block's top C Ritz vectors), and every later block is C wide, started from
// all of the block before: the basis is Q_1 plus the block Krylov space K_k(B B^T, B B^T Q_1 E).
// The oversampled first block gives the start its accuracy; the later passes cost C columns, not
// l. At UBO2003 size (docs/benchmarks.md) rank 32 and 64 at q 4, p 16 reach the same error in as
// many passes, 21-24 % faster. Not at q = 1: there the narrow block 2 is the last one and costs
// accuracy (rank 32 p 8: 1.0155 x the optimum against 1.0092), which more oversampling buys back
// for ~3 % of the time in core and none in the stream (ooc_svd.h, whose pass 1 is l wide either
// way). Taking Q_1's columns in the sketch's order instead of the Ritz vectors' (no
// eigenvectors, as one read per block would allow) lost 1-2 % of error: not used.

// out = A M (rows x cols, float) for a tall A (float or double), in blocks of rows: the double
// product of a block at a time, so no rows x cols double temporary (its fresh pages cost more
// than the product).
template <class A, class M>
void rows_times(const A& a, const M& mat, MatrixXfR& out) {
  constexpr Index k_rows = 4096;
  MatrixXd block;
  for (Index i = 0; i < a.rows(); i += k_rows) {
    const Index h = std::min(k_rows, a.rows() - i);
    block.noalias() = a.middleRows(i, h).template cast<double>() * mat;
    out.middleRows(i, h) = block.cast<float>();
  }
}

// A column-major matrix in huge-page scratch memory (core/memory.h): the Krylov basis and W^T
// are the SVD's largest buffers (19683 x 80 doubles and 65536 x 80 floats at rank 32). Not zeroed.
template <class Scalar>
class PageMatrix {
  using Mat = Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic>;

 public:
  PageMatrix(Index rows, Index cols) : m_buf(size_t(rows) * size_t(cols)), map(m_buf.data(), rows, cols) {}
  Eigen::Map<Mat>& operator*() { return map; }

 private:
  PageBuffer<Scalar> m_buf;
  Eigen::Map<Mat> map;
};

Result<SvdResult> krylov_svd(ConstMapF& B, const SvdOptions& opt) {
  const Index m = B.rows(), n = B.cols(), small = std::min(m, n);
  const Index l = std::min<Index>(small, Index(opt.max_rank) + opt.oversample);
  const int max_blocks = std::max(1, int(std::min<Index>(opt.power_iters + 1, std::max<Index>(1, small / l))));
  if (opt.progress) opt.progress->start("fmf randomized SVD (block Krylov)", uint64_t(2 * max_blocks));
  auto step = [&] { if (opt.progress) opt.progress->advance(); };
  SvdResult r;
  r.method = "randomized";
  r.requested_rank = opt.max_rank;
  // The passes run btfc's OpenMP kernels; OpenBLAS's own pool, woken by the small products in
  // between (the orthonormalisation, the Ritz step), would spin (sched_yield) against them for the
  // 2 cores: 3.04-3.37 s against 2.80-2.89 s for the streamed SVD, which holds one BLAS thread
  // (ooc_svd.cpp), at rank 32 q 1 at UBO2003 size. Not from l = 256 on: there the products in
  // between are GEMMs of seconds (orthonormalize_against's projections on a basis of thousands of
  // columns, in double) that one thread ran for most of a rank-1024 SVD (docs/benchmarks.md).
  const SingleThreadedBlas one_blas_thread(l < 256);

  // Blocks after the first hold lk = min(l, C) columns when there can be three blocks or more,
  // started from the top lk Ritz vectors of the first block (the comment above).
  const Index lk = later_krylov_width(max_blocks, l, opt.max_rank);
  // Few and small buffers, allocated once: fresh memory costs its page faults (1-6 ms per MB on
  // the VMs measured, docs/benchmarks.md), a sizeable part of a pass. W^T is the passes' own
  // float output (no double copy: the Gram matrix and the Ritz step convert it by blocks), and
  // block i's B^T Q_i is also the next block's B X operand.
  const Index width = l + Index(max_blocks - 1) * lk;
  PageMatrix<double> q_buf(m, width);
  PageMatrix<float> wt_buf(n, width);
  {  // the first two blocks, which every run fills, faulted on all threads (core/memory.h)
    const size_t used = size_t(std::min(width, l + lk));
    page_touch((*q_buf).data(), size_t(m) * used * sizeof(double));
    page_touch((*wt_buf).data(), size_t(n) * used * sizeof(float));
  }
  auto& Q = *q_buf;    // the orthonormal Krylov basis: l columns, then lk per block
  auto& Wt = *wt_buf;  // B^T Q, block by block
  MatrixXd G(width, width);  // W W^T = Wt^T Wt in double, grown block by block
  MatrixXf Y(m, l), Qf(m, l), X1;
  {
    const Sketch sketch = make_column_sketch(size_t(n), l, opt);
    r.sparse_start = sketch.sparse();
    r.total_energy = 0;
    column_sketch_product(B.data(), size_t(m), size_t(n), sketch, Y, &r.total_energy);  // B Pi, and ||B||_F^2
  }
  if (!std::isfinite(r.total_energy)) return non_finite_input();  // truncated_svd's contract (svd.h)
  step();
  int blocks = 0;
  Index g_cols = 0;  // columns of G filled
  double last_err = -1;
  auto grow_gram = [&](Index w) {  // G's columns [g_cols, w) from Wt
    const MatrixXd part = gram_columns(Wt.leftCols(w), g_cols);
    G.block(0, g_cols, w, w - g_cols) = part;
    G.block(g_cols, 0, w - g_cols, g_cols) = part.topRows(g_cols).transpose();
    g_cols = w;
  };
  Index used = 0, bw = l;  // columns before the block, the block's
  while (true) {
    const Index w = used + bw;
    auto X = Q.middleCols(used, bw);
    X = Y.leftCols(bw).cast<double>();
    orthonormalize_against(Q, used, X);
    Qf.leftCols(bw) = X.cast<float>();
    product_bt(B, Qf.leftCols(bw), Wt.middleCols(used, bw));  // n x bw
    step();
    ++blocks;
    grow_gram(w);
    if (blocks == max_blocks) break;
    // Error-driven stop: the rank-C error of the current basis, from the eigenvalues of W W^T
    // (in double: the residual is a small difference of large sums).
    Eigen::VectorXd ev;
    MatrixXd vecs;
    const bool select = bw > lk;  // the first block, when wider than the later ones
    symmetric_eigen(G.topLeftCorner(w, w), ev, select ? &vecs : nullptr);
    const Index c = std::min<Index>(opt.max_rank, w);
    const double kept = ev.tail(c).cwiseMax(0.0).sum();
    const double err = r.total_energy > 0 ? std::sqrt(std::max(0.0, r.total_energy - kept) / r.total_energy) : 0;
    if (blocks >= 2 && last_err - err <= k_krylov_stop * err) break;
    last_err = err;
    // The next block's start, B B^T Q_i (B^T Q_i as it is: its columns' scales, ~ the singular
    // values, do not cost float accuracy, each column of the product being its own sum), or
    // B B^T (Q_1 E) for the first block's top lk Ritz vectors Q_1 E (ascending eigenvalues: E is
    // the last lk eigenvectors; B^T Q_1 E = W_1^T E). The block is made orthonormal, in double,
    // after the product.
    if (select) {
      X1 = Wt.leftCols(w) * vecs.rightCols(lk).cast<float>();
      product_b(B, X1, Y.leftCols(lk));  // m x lk
    } else {
      product_b(B, Wt.middleCols(used, bw), Y.leftCols(bw));  // m x bw
    }
    step();
    used = w;
    bw = lk;
  }
  const Index w = used + bw;
  r.iterations = blocks;
  Eigen::VectorXd lambda;
  MatrixXd E;
  top_eigenpairs(G.topLeftCorner(w, w), w, lambda, E);
  const int rank = choose_rank(lambda, r.total_energy, opt, r.data_rank_limit, r.target_reached);
  r.S = lambda.head(rank).cwiseSqrt();
  r.kept_energy = lambda.head(rank).sum();
  const MatrixXd Ek = E.leftCols(rank);
  r.U.resize(m, rank);
  r.SxV.resize(n, rank);
  rows_times(Q.leftCols(w), Ek, r.U);
  rows_times(Wt.leftCols(w), Ek, r.SxV);
  if (opt.progress) opt.progress->finish();
  return r;
}

Result<SvdResult> randomized_svd(ConstMapF& B, const SvdOptions& opt) {
  return opt.scheme == RandomizedScheme::block_krylov ? krylov_svd(B, opt) : power_svd(B, opt);
}

}  // namespace

// No double copy of B exists (B^T B once copied all of it: 3.4 x the input's peak memory, and
// page faults were most of the encode of a 32 x 32 texel BTF).
Index exact_double_block(Index len) { return Index(std::clamp<Index>((Index(32) << 20) / 8 / std::max<Index>(len, 1), 1, 4096)); }

int choose_rank(const Eigen::VectorXd& lambda, double total, const SvdOptions& opt, int& data_rank, bool& reached) {
  const Index k = lambda.size();
  const double floor = lambda.size() ? lambda(0) * k_rel_sigma_floor * k_rel_sigma_floor : 0;
  data_rank = 0;
  while (data_rank < k && lambda(data_rank) > floor && lambda(data_rank) > 0) ++data_rank;
  int rank = std::min<int>(opt.max_rank, data_rank);
  reached = true;
  if (opt.target_rel_error > 0 && total > 0) {
    const double allowed = opt.target_rel_error * opt.target_rel_error * total;
    double kept = 0;
    int r = 0;
    while (r < rank && total - kept > allowed) kept += lambda(r++);
    reached = total - kept <= allowed * (1 + 1e-9);
    rank = r;
  }
  return std::max(rank, 1);
}

namespace {

#ifdef BTFC_HAVE_OPENBLAS
// All eigenvalues (and with `vectors`, eigenvectors) by dsyevd, ascending; false when LAPACK
// reports a failure (then Eigen's solver runs).
bool lapack_eigen(const MatrixXd& G, Eigen::VectorXd& w, MatrixXd& A, bool vectors = true) {
  if (G.rows() > INT_MAX / 4) return false;
  const int n = int(G.rows());
  const char* jobz = vectors ? "V" : "N";
  A = G;  // column-major, overwritten by the eigenvectors
  w.resize(n);
  int info = 0, lwork = -1, liwork = -1, iwork_query = 0;
  double work_query = 0;
  dsyevd_(jobz, "L", &n, A.data(), &n, w.data(), &work_query, &lwork, &iwork_query, &liwork, &info, 1, 1);
  if (info != 0) return false;
  lwork = int(work_query);
  liwork = iwork_query;
  std::vector<double> work(size_t(std::max(lwork, 1)));
  std::vector<int> iwork(size_t(std::max(liwork, 1)));
  dsyevd_(jobz, "L", &n, A.data(), &n, w.data(), work.data(), &lwork, iwork.data(), &liwork, &info, 1, 1);
  return info == 0 && w.allFinite();
}
#endif

}  // namespace

void symmetric_eigen(const MatrixXd& G, Eigen::VectorXd& ascending, MatrixXd* vecs, Index lapack_from) {
#ifdef BTFC_HAVE_OPENBLAS
  if (G.rows() >= lapack_from) {
    MatrixXd A;
    if (lapack_eigen(G, ascending, A, vecs != nullptr)) {
      if (vecs) *vecs = std::move(A);
      return;
    }
  }
#else
  (void)lapack_from;
#endif
  Eigen::SelfAdjointEigenSolver<MatrixXd> es(G, vecs ? Eigen::ComputeEigenvectors : Eigen::EigenvaluesOnly);
  ascending = es.eigenvalues();
  if (vecs) *vecs = es.eigenvectors();
}

void top_eigenpairs(const MatrixXd& G, Index l, Eigen::VectorXd& lambda, MatrixXd& vecs, Index lapack_from) {
  const Index k = G.rows();
#ifdef BTFC_HAVE_OPENBLAS
  if (k >= lapack_from) {
    Eigen::VectorXd w;
    MatrixXd A;
    if (lapack_eigen(G, w, A)) {
      lambda.resize(l);
      vecs.resize(k, l);
      for (Index i = 0; i < l; ++i) {  // ascending, as Eigen's
        lambda(i) = std::max(0.0, w(k - 1 - i));
        vecs.col(i) = A.col(k - 1 - i);
      }
      return;
    }
  }
#endif
  Eigen::SelfAdjointEigenSolver<MatrixXd> es(G);
  lambda.resize(l);
  vecs.resize(k, l);
  for (Index i = 0; i < l; ++i) {  // Eigen returns ascending order
    lambda(i) = std::max(0.0, es.eigenvalues()(k - 1 - i));
    vecs.col(i) = es.eigenvectors().col(k - 1 - i);
  }
}

namespace {

// r's leading `rank` components (all of them when it has fewer), as a rank-`rank` result.
SvdResult leading(const SvdResult& r, int rank) {
  SvdResult t;
  const Index k = std::min<Index>(rank, r.S.size());
  t.U = r.U.leftCols(k);
  t.SxV = r.SxV.leftCols(k);
  t.S = r.S.head(k);
  t.total_energy = r.total_energy;
  t.kept_energy = r.S.head(k).squaredNorm();
  t.method = r.method;
  t.requested_rank = rank;
  t.data_rank_limit = r.data_rank_limit;
  t.iterations = r.iterations;
  t.sparse_start = r.sparse_start;
  return t;
}

// The rank a reuse scope computes for a request of rank r: twice the request, and at least twice
// the kept one (the ranks computed in a search grow geometrically, so together they cost about
// two of the largest), rounded up to 64, at most the scope's rank, then the largest rank up to
// that which `randomized` accepts (the automatic choice still factorizes it randomized; r's is).
int wanted_rank(int r, int kept, int scope_rank) { return std::max(r, std::min(scope_rank, (std::max(2 * r, 2 * kept) + 63) / 64 * 64)); }
int grown_rank(int r, int kept, int scope_rank, const std::function<bool(int)>& randomized) {
  int lo = r, hi = wanted_rank(r, kept, scope_rank);
  while (lo < hi) {
    const int mid = lo + (hi - lo + 1) / 2;
    if (randomized(mid))
      lo = mid;
    else
      hi = mid - 1;
  }
  return lo;
}
// Whether the randomized path's range cut a request's growth: `grown` (grown_rank's) below what
// the scope wanted for it. Such a request goes exact where the exact path is kept.
bool growth_capped(int grown, int r, int kept, int scope_rank) { return grown < wanted_rank(r, kept, scope_rank); }

// RandomizedSvdReuse (svd.h): the kept factorization's leading components when it matches,
// else a new one at the scope's rank for this request, kept when larger; null outside a scope.
Result<std::optional<SvdResult>> reused_randomized(ConstMapF& B, const SvdOptions& opt) {
  int scope_rank = 0;
  {
    std::lock_guard<std::mutex> lock(g_reuse_mutex);
    scope_rank = g_randomized_scopes > 0 ? g_randomized_rank : 0;
  }
  if (!opt.truncation_ok || opt.target_rel_error > 0 || opt.max_rank > scope_rank) return std::optional<SvdResult>{};
  const uint64_t fp = fingerprint(B);
  auto same = [&](const KeptRandomized& k) {
    return k.fingerprint == fp && k.m == B.rows() && k.n == B.cols() && k.oversample == opt.oversample && k.power_iters == opt.power_iters &&
           k.scheme == int(opt.scheme) && k.seed == opt.seed && k.sparse == opt.sparse_sketch;
  };
  int kept_rank = 0;
  bool gram_kept = false, exact_kept = false;
  {
    std::lock_guard<std::mutex> lock(g_reuse_mutex);
    if (g_kept_randomized && same(*g_kept_randomized)) {
      kept_rank = g_kept_randomized->rank;
      if (kept_rank >= opt.max_rank) {
        ++g_randomized_served;
        return std::optional<SvdResult>(leading(g_kept_randomized->r, opt.max_rank));
      }
    }
    exact_kept = g_reuse_scopes > 0;
    gram_kept = exact_kept && find_gram(fp, B.rows(), B.cols()) != g_reuse.end();
  }
  SvdOptions big = opt;
  big.max_rank = grown_rank(opt.max_rank, kept_rank, scope_rank, [&](int rank) {
    SvdOptions t = opt;
    t.max_rank = rank;
    return resolved_method(size_t(B.rows()), size_t(B.cols()), t) == SvdMethod::randomized;
  });
  // The exact path instead, where the automatic choice allows it and a search keeps its Gram
  // eigenpairs (ExactSvdReuse): when a probe has computed them already (any rank is then one
  // projection away: 1-2 s on the textile at ranks 400-1000, where a randomized SVD of grown rank
  // took 6-12 s), or when the growth is capped by the randomized path's range (a small side the
  // exact path serves, where a rank past an eighth of it is factorized exactly anyway: the grown
  // randomized SVD would cost about as much as the Gram, and serve fewer ranks). The randomized
  // path's input check (svd_checks_finite) is kept: one read of B.
  const bool capped = growth_capped(big.max_rank, opt.max_rank, kept_rank, scope_rank);
  if (opt.method == SvdMethod::automatic && (gram_kept || (capped && exact_kept))) {
    if (find_non_finite(B.data(), size_t(B.size())) < size_t(B.size())) return non_finite_input();
    BTFC_ASSIGN_OR_RETURN(SvdResult r, exact_svd(B, opt, fp));
    return std::optional<SvdResult>(std::move(r));
  }
  BTFC_ASSIGN_OR_RETURN(SvdResult r, randomized_svd(B, big));
  std::lock_guard<std::mutex> lock(g_reuse_mutex);
  ++g_randomized_computed, ++g_randomized_served;
  SvdResult t = leading(r, opt.max_rank);
  if (g_randomized_scopes > 0 && (!g_kept_randomized || !same(*g_kept_randomized) || g_kept_randomized->rank < big.max_rank)) {
    auto k = std::make_unique<KeptRandomized>();
    k->fingerprint = fp, k->m = B.rows(), k->n = B.cols(), k->oversample = opt.oversample, k->power_iters = opt.power_iters;
    k->scheme = int(opt.scheme), k->seed = opt.seed, k->sparse = opt.sparse_sketch, k->rank = big.max_rank;
    k->r = std::move(r);
    g_kept_randomized = std::move(k);
  }
  return std::optional<SvdResult>(std::move(t));
}

}  // namespace

Result<SvdResult> truncated_svd(const float* B, size_t m, size_t n, const SvdOptions& opt) {
  if (m == 0 || n == 0) return invalid_argument("SVD of an empty matrix");
  if (opt.max_rank < 1) return invalid_argument("SVD rank must be >= 1");
  ConstMapF map(B, Index(m), Index(n));
  if (resolved_method(m, n, opt) == SvdMethod::exact) return exact_svd(map, opt);
  BTFC_ASSIGN_OR_RETURN(std::optional<SvdResult> kept, reused_randomized(map, opt));
  if (kept) return std::move(*kept);
  return randomized_svd(map, opt);
}

bool svd_checks_finite(size_t m, size_t n, const SvdOptions& opt) { return resolved_method(m, n, opt) == SvdMethod::randomized; }

SvdMethod resolved_method(size_t m, size_t n, const SvdOptions& opt) {
  SvdMethod method = opt.method;
  const size_t small = std::min(m, n);
  if (method == SvdMethod::automatic)
    method = small <= 1024 || (small <= k_exact_auto_max && size_t(opt.max_rank + opt.oversample) * 8 >= small) ? SvdMethod::exact
                                                                                                          : SvdMethod::randomized;
  // The randomized sketch cannot exceed the small side; then the exact path is both exact and cheap.
  if (method == SvdMethod::randomized && size_t(opt.max_rank) + size_t(opt.oversample) >= small) method = SvdMethod::exact;
  return method;
}

ExactSvdReuse::ExactSvdReuse() {
  std::lock_guard<std::mutex> lock(g_reuse_mutex);
  ++g_reuse_scopes;
}

ExactSvdReuse::~ExactSvdReuse() {
  std::lock_guard<std::mutex> lock(g_reuse_mutex);
  if (--g_reuse_scopes == 0) g_reuse.clear();
}

RandomizedSvdReuse::RandomizedSvdReuse(int max_rank) {
  std::lock_guard<std::mutex> lock(g_reuse_mutex);
  if (g_randomized_scopes++ == 0) g_randomized_rank = max_rank;
}

RandomizedSvdReuse::~RandomizedSvdReuse() {
  std::lock_guard<std::mutex> lock(g_reuse_mutex);
  if (--g_randomized_scopes == 0) g_kept_randomized.reset(), g_kept_set.reset(), g_randomized_rank = 0;
}

uint64_t data_fingerprint(const float* data, size_t n) {
  ConstMapF map(data, Index(n), 1);
  return fingerprint(map);
}

namespace {

// The kept set of factorizations for `key` with n matrices, or null. Under g_reuse_mutex.
const KeptSet* kept_set_for(uint64_t key, size_t n) {
  return g_kept_set && g_kept_set->key == key && g_kept_set->ranks.size() == n ? g_kept_set.get() : nullptr;
}

RandomizedSvdReuse::Set leading_set(const RandomizedSvdReuse::Set& s, const std::vector<int>& ranks) {
  RandomizedSvdReuse::Set t;
  t.extra = s.extra;
  for (size_t i = 0; i < s.r.size(); ++i) t.r.push_back(leading(s.r[i], ranks[i]));
  return t;
}

}  // namespace

Result<RandomizedSvdReuse::Set> RandomizedSvdReuse::serve_set(uint64_t key, const std::vector<int>& ranks,
                                                              const std::function<bool(int)>& randomized_at,
                                                              const std::function<Result<Set>(const std::vector<int>&)>& compute) {
  std::vector<int> big;  // the kept ranks, then the ranks to compute
  int scope_rank = 0;
  {
    std::lock_guard<std::mutex> lock(g_reuse_mutex);
    if (g_randomized_scopes == 0) return compute(ranks);
    const KeptSet* k = kept_set_for(key, ranks.size());
    bool covered = k != nullptr;
    for (size_t i = 0; covered && i < ranks.size(); ++i) covered = k->ranks[i] >= ranks[i];
    if (covered) {
      ++g_randomized_served;
      return leading_set(k->set, ranks);
    }
    for (size_t i = 0; i < ranks.size(); ++i) big.push_back(k ? k->ranks[i] : 0);
    scope_rank = g_randomized_rank;
  }
  for (size_t i = 0; i < big.size(); ++i)  // a covered matrix keeps its kept rank
    if (big[i] < ranks[i]) big[i] = grown_rank(ranks[i], big[i], scope_rank, randomized_at);
  BTFC_ASSIGN_OR_RETURN(Set computed, compute(big));
  std::lock_guard<std::mutex> lock(g_reuse_mutex);
  ++g_randomized_computed, ++g_randomized_served;
  Set t = leading_set(computed, ranks);
  if (g_randomized_scopes > 0) {
    auto k = std::make_unique<KeptSet>();
    k->key = key, k->ranks = std::move(big), k->set = std::move(computed);
    g_kept_set = std::move(k);
  }
  return t;
}

bool RandomizedSvdReuse::grows_past_randomized(uint64_t key, const std::vector<int>& ranks, const std::function<bool(int)>& randomized_at) {
  std::vector<int> kept(ranks.size(), 0);
  int scope_rank = 0;
  {
    std::lock_guard<std::mutex> lock(g_reuse_mutex);
    if (g_randomized_scopes == 0 || g_reuse_scopes == 0) return false;
    if (const KeptSet* k = kept_set_for(key, ranks.size())) kept = k->ranks;
    scope_rank = g_randomized_rank;
  }
  for (size_t i = 0; i < ranks.size(); ++i)
    if (kept[i] < ranks[i] && growth_capped(grown_rank(ranks[i], kept[i], scope_rank, randomized_at), ranks[i], kept[i], scope_rank))
      return true;
  return false;
}

bool RandomizedSvdReuse::active() {
  std::lock_guard<std::mutex> lock(g_reuse_mutex);
  return g_randomized_scopes > 0;
}

size_t RandomizedSvdReuse::computed() {
  std::lock_guard<std::mutex> lock(g_reuse_mutex);
  return g_randomized_computed;
}

size_t RandomizedSvdReuse::served() {
  std::lock_guard<std::mutex> lock(g_reuse_mutex);
  return g_randomized_served;
}

size_t ExactSvdReuse::reuses() {
  std::lock_guard<std::mutex> lock(g_reuse_mutex);
  return g_reuses;
}

size_t ExactSvdReuse::projected_columns() {
  std::lock_guard<std::mutex> lock(g_reuse_mutex);
  return g_projected_columns;
}

}  // namespace btfc
