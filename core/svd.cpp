// Truncated SVD for fmf; see svd.h for the contract and the choice of paths.
#include "core/svd.h"

#include <Eigen/Dense>
#include <algorithm>
#include <climits>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <list>
#include <mutex>
#include <random>
#include <vector>

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#define BTFC_THIN_TN_AVX512 1
#endif

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

// All eigenpairs, sorted by descending eigenvalue.
void sorted_eigen(const MatrixXd& G, Eigen::VectorXd& lambda, MatrixXd& vecs) { top_eigenpairs(G, G.rows(), lambda, vecs); }

double frobenius2(ConstMapF& B) {
  double total = 0;
  const Index n = B.cols();
#pragma omp parallel for reduction(+ : total) schedule(static)
  for (Index j = 0; j < n; ++j) total += B.col(j).cast<double>().squaredNorm();
  return total;
}

// ExactSvdReuse's store: the eigendecompositions of the last few Gram matrices, by fingerprint.
struct GramEigen {
  uint64_t fingerprint = 0;
  Index m = 0, n = 0;
  Eigen::VectorXd lambda;
  MatrixXd E;
};
std::mutex g_reuse_mutex;
int g_reuse_scopes = 0;
size_t g_reuses = 0;
std::list<GramEigen> g_reuse;  // most recent first
constexpr size_t k_reuse_entries = 3;  // dfmf factorizes three channel matrices per encode

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
// double, eigenvalues descending.
void gram_eigen(ConstMapF& B, bool rows_small, const SvdOptions& opt, Eigen::VectorXd& lambda, MatrixXd& E) {
  const Index n = B.cols(), k = rows_small ? B.rows() : n;
  // B B^T is accumulated over column blocks so no double copy of B exists. B^T B (n < m: fewer
  // texels than rows) uses one double copy of B: 2x the input, 645 MB for the 64 x 64 textile,
  // whose ranks above 1/8 of its 4096 texels now take this path.
  MatrixXd G = MatrixXd::Zero(k, k);
  const Index block = 4096;
  // One step per Gram block, one for the eigendecomposition, one for the projection.
  if (opt.progress) opt.progress->start("fmf exact SVD", uint64_t((n + block - 1) / block) + 2);
  if (rows_small) {
    for (Index j0 = 0; j0 < n; j0 += block) {
      const Index nb = std::min(block, n - j0);
      MatrixXd Bd = B.middleCols(j0, nb).cast<double>();
      G.selfadjointView<Eigen::Lower>().rankUpdate(Bd);
      if (opt.progress) opt.progress->advance();
    }
    G.triangularView<Eigen::StrictlyUpper>() = G.transpose();
  } else {
    MatrixXd Bd = B.cast<double>();
    G.noalias() = Bd.transpose() * Bd;
    if (opt.progress) opt.progress->advance((n + block - 1) / block);
  }
  sorted_eigen(G, lambda, E);
  if (opt.progress) opt.progress->advance();
}

Result<SvdResult> exact_svd(ConstMapF& B, const SvdOptions& opt) {
  const Index m = B.rows(), n = B.cols();
  const bool rows_small = m <= n;
  Eigen::VectorXd lambda;
  MatrixXd E;
  // The lock is held to look up and to store, not while computing: codecs factorize several
  // matrices in parallel.
  bool reuse = false, reused = false;
  uint64_t fp = 0;
  {
    std::lock_guard<std::mutex> lock(g_reuse_mutex);
    reuse = g_reuse_scopes > 0;
  }
  if (reuse) {
    fp = fingerprint(B);
    std::lock_guard<std::mutex> lock(g_reuse_mutex);
    auto it = std::find_if(g_reuse.begin(), g_reuse.end(), [&](const GramEigen& e) { return e.fingerprint == fp && e.m == m && e.n == n; });
    if (it != g_reuse.end()) {
      lambda = it->lambda;
      E = it->E;
      g_reuse.splice(g_reuse.begin(), g_reuse, it);
      ++g_reuses;
      reused = true;
    }
  }
  if (reused) {
    if (opt.progress) opt.progress->start("fmf exact SVD (reused)", 1);
  } else {
    gram_eigen(B, rows_small, opt, lambda, E);
    if (reuse) {
      std::lock_guard<std::mutex> lock(g_reuse_mutex);
      if (g_reuse_scopes > 0) {
        g_reuse.push_front(GramEigen{fp, m, n, lambda, E});
        if (g_reuse.size() > k_reuse_entries) g_reuse.pop_back();
      }
    }
  }
  SvdResult r;
  r.method = "exact";
  r.requested_rank = opt.max_rank;
  r.total_energy = lambda.sum();  // trace(G) = ||B||_F^2, in double
  const int rank = choose_rank(lambda, r.total_energy, opt, r.data_rank_limit, r.target_reached);
  r.S = lambda.head(rank).cwiseSqrt();
  r.kept_energy = lambda.head(rank).sum();
  if (rows_small) {
    // U = top eigenvectors of B B^T; SxV = B^T U is the projection (no division by sigma).
    MatrixXd U = E.leftCols(rank);
    MatrixXd SxV = B.cast<double>().transpose() * U;
    r.U = U.cast<float>();
    r.SxV = SxV.cast<float>();
  } else {
    // V = top eigenvectors of B^T B; U = B V / sigma; SxV = V sigma. Kept sigma > floor > 0,
    // except for all-zero input, where U is left zero.
    MatrixXd V = E.leftCols(rank);
    MatrixXd U = B.cast<double>() * V;
    for (int c = 0; c < rank; ++c) U.col(c) *= r.S(c) > 0 ? 1.0 / r.S(c) : 0.0;
    r.U = U.cast<float>();
    r.SxV = (V * r.S.asDiagonal()).cast<float>();
  }
  if (opt.progress) opt.progress->finish();
  return r;
}

// Z = B^T Y for the passes of the randomized SVD: B m x n column-major (the data, never copied),
// Y m x l, l <= ~150. OpenBLAS runs this shape (65536 x 19683 times 19683 x 48) at about a third
// of the machine's SGEMM rate: it packs B, the large operand, for a product of only l columns.
// This kernel reads B once, in place: 8 texel columns at a time, their values broadcast against
// a row of Y (row-major, l values = NV zmm registers) into 8 x NV accumulators, with the rows in
// chunks whose slice of Y stays in L2. Measured at 1.7-2.4x OpenBLAS's rate for this product on
// the 2 cores (docs/benchmarks.md). AVX-512 only, chosen at run time (the default build is
// portable); elsewhere the product stays an Eigen (OpenBLAS) GEMM. Each output is one
// sequential sum per lane over the rows, so results do not depend on the thread count.
#ifdef BTFC_THIN_TN_AVX512
template <int NV, int TJ>
__attribute__((target("avx512f"))) void thin_tn_tile_avx512(const float* B, size_t ldb, const float* Yr, size_t k0, size_t k1,
                                                            size_t j0, float* Zr, bool first) {
  constexpr int L = 16 * NV;
  __m512 acc[TJ][NV];
  for (int t = 0; t < TJ; ++t)
    for (int v = 0; v < NV; ++v) acc[t][v] = first ? _mm512_setzero_ps() : _mm512_loadu_ps(Zr + (j0 + t) * L + 16 * v);
  const float* col[TJ];
  for (int t = 0; t < TJ; ++t) col[t] = B + (j0 + t) * ldb;
  for (size_t k = k0; k < k1; ++k) {
    __m512 y[NV];
    for (int v = 0; v < NV; ++v) y[v] = _mm512_loadu_ps(Yr + k * L + 16 * v);
    for (int t = 0; t < TJ; ++t) {
      const __m512 b = _mm512_set1_ps(col[t][k]);
      for (int v = 0; v < NV; ++v) acc[t][v] = _mm512_fmadd_ps(b, y[v], acc[t][v]);
    }
  }
  for (int t = 0; t < TJ; ++t)
    for (int v = 0; v < NV; ++v) _mm512_storeu_ps(Zr + (j0 + t) * L + 16 * v, acc[t][v]);
}

// Yr: m x 16 NV row-major (zero-padded columns); Zr: n x 16 NV row-major.
template <int NV>
void thin_tn(const float* B, size_t m, size_t n, const float* Yr, float* Zr) {
  constexpr int TJ = std::min(16, (31 - NV) / NV);  // TJ x NV accumulators + NV of Y + 1 broadcast <= 32 registers
  constexpr size_t k_rows = 2048;   // a chunk of Y's rows: 2048 x 16 NV floats, in L2
  constexpr size_t k_texels = 64;   // texels per parallel task
  const int64_t tasks = int64_t((n + k_texels - 1) / k_texels);
#pragma omp parallel for schedule(dynamic, 1)
  for (int64_t s = 0; s < tasks; ++s) {
    const size_t j0 = size_t(s) * k_texels, j1 = std::min(n, j0 + k_texels);
    for (size_t k0 = 0; k0 < m; k0 += k_rows) {
      const size_t k1 = std::min(m, k0 + k_rows);
      size_t j = j0;
      for (; j + TJ <= j1; j += TJ) thin_tn_tile_avx512<NV, TJ>(B, m, Yr, k0, k1, j, Zr, k0 == 0);
      for (; j < j1; ++j) thin_tn_tile_avx512<NV, 1>(B, m, Yr, k0, k1, j, Zr, k0 == 0);
    }
  }
}

bool have_avx512() {
  static const bool yes = [] {
    __builtin_cpu_init();
    return __builtin_cpu_supports("avx512f");
  }();
  return yes;
}
#endif

}  // namespace

void product_bt(ConstMapF& B, const MatrixXf& Y, MatrixXf& Z) {
#ifdef BTFC_THIN_TN_AVX512
  const Index l = Y.cols(), nv = (l + 15) / 16;
  if (have_avx512() && nv >= 1 && nv <= 8) {
    const Index m = B.rows(), n = B.cols(), L = 16 * nv;
    MatrixXfR Yr = MatrixXfR::Zero(m, L), Zr(n, L);
    Yr.leftCols(l) = Y;
    using Fn = void (*)(const float*, size_t, size_t, const float*, float*);
    static constexpr Fn k_fns[8] = {thin_tn<1>, thin_tn<2>, thin_tn<3>, thin_tn<4>, thin_tn<5>, thin_tn<6>, thin_tn<7>, thin_tn<8>};
    k_fns[nv - 1](B.data(), size_t(m), size_t(n), Yr.data(), Zr.data());
    Z = Zr.leftCols(l);
    return;
  }
#endif
  Z.noalias() = B.transpose() * Y;
}

void transposed_product(const float* B, size_t m, size_t n, const Eigen::MatrixXf& Y, Eigen::MatrixXf& Z) {
  ConstMapF map(B, Index(m), Index(n));
  product_bt(map, Y, Z);
}

namespace {

// Orthonormal basis of the columns of Y (thin Householder QR in double for stability).
MatrixXf orthonormalize(const MatrixXf& Y) {
  MatrixXd Yd = Y.cast<double>();
  Eigen::HouseholderQR<MatrixXd> qr(Yd);
  MatrixXd Q = qr.householderQ() * MatrixXd::Identity(Y.rows(), Y.cols());
  return Q.cast<float>();
}

// Gaussian test matrix (rows x cols) from a seeded engine: Box-Muller on raw 64-bit draws so
// the numbers do not depend on the standard library's distribution implementation.
MatrixXf gaussian(Index rows, Index cols, uint64_t seed) {
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

Result<SvdResult> power_svd(ConstMapF& B, const SvdOptions& opt) {
  const Index m = B.rows(), n = B.cols();
  const Index l = std::min<Index>(std::min(m, n), Index(opt.max_rank) + opt.oversample);
  if (opt.progress) opt.progress->start("fmf randomized SVD", uint64_t(2 * opt.power_iters + 3));
  auto step = [&] { if (opt.progress) opt.progress->advance(); };

  MatrixXf Omega = gaussian(n, l, opt.seed);
  SvdResult r;
  r.method = "randomized";
  r.requested_rank = opt.max_rank;
  r.total_energy = frobenius2(B);
  step();

  MatrixXf Y = B * Omega;  // m x l
  Omega.resize(0, 0);
  step();
  MatrixXf Q = orthonormalize(Y);
  MatrixXf Z;
  for (int it = 0; it < opt.power_iters; ++it) {
    product_bt(B, Q, Z);  // n x l
    step();
    Z = orthonormalize(Z);
    Y.noalias() = B * Z;
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



// X := an orthonormal basis of X's columns orthogonal to P's: block classical Gram-Schmidt and
// Householder QR, twice ("twice is enough"; the second round after normalising, so a block that
// is noise after the projection, as when the Krylov space has exhausted B's range, is still made
// orthogonal to P to round-off). The projections are n x (used) x l double GEMMs.
void orthonormalize_against(const MatrixXd& P, Index used, MatrixXd& X) {
  auto project = [&] {
    if (used == 0) return;
    const auto Pu = P.leftCols(used);
    MatrixXd C = Pu.transpose() * X;
    X.noalias() -= Pu * C;
  };
  auto qr = [&] {
    Eigen::HouseholderQR<MatrixXd> h(X);
    X = h.householderQ() * MatrixXd::Identity(X.rows(), X.cols());
  };
  project();
  qr();
  if (used > 0) {
    project();
    qr();
  }
}

// Randomized block Krylov SVD (Musco and Musco 2015; the Ritz step of Halko et al. 2011,
// section 4.3, on the right-hand side): blocks X_1 = orth(B^T Omega), X_{i+1} = orth(B^T B X_i)
// with every block kept and made orthogonal to the earlier ones, so P = [X_1 .. X_k] is an
// orthonormal basis of the Krylov space K_k(B^T B, B^T Omega). Each block costs two passes
// over B (B^T Y and Y = B X), as one power iteration does, but the basis grows by l columns per
// block instead of being replaced, which takes the rank-C error to the Eckart-Young optimum in
// fewer passes (measured on the UBO2003-size matrix in docs/benchmarks.md). B P = [Y_1 .. Y_k]
// is already known from the passes, so the Ritz step (the SVD of B P) needs no further pass:
// B ~ (B P) P^T, and with B P = Qy R, R = Ur S Vr^T, U = Qy Ur and SxV = P Vr S. The error of
// B P P^T truncated to rank C is ||B||^2 - sum of the C largest S^2, the same estimate as before.
// Stops early, after at least two blocks, when a block improved that rank-C error by less than
// k_krylov_stop of itself (the remaining gap to the optimum then is a fraction of that), and
// before the basis would exceed the small side of B.
constexpr double k_krylov_stop = 2e-3;

Result<SvdResult> krylov_svd(ConstMapF& B, const SvdOptions& opt) {
  const Index m = B.rows(), n = B.cols(), small = std::min(m, n);
  const Index l = std::min<Index>(small, Index(opt.max_rank) + opt.oversample);
  const int max_blocks = std::max(1, int(std::min<Index>(opt.power_iters + 1, std::max<Index>(1, small / l))));
  if (opt.progress) opt.progress->start("fmf randomized SVD (block Krylov)", uint64_t(2 * max_blocks + 1));
  auto step = [&] { if (opt.progress) opt.progress->advance(); };
  SvdResult r;
  r.method = "randomized";
  r.requested_rank = opt.max_rank;
  r.total_energy = frobenius2(B);
  step();

  const Index width = Index(max_blocks) * l;
  MatrixXd P(n, width);   // the orthonormal Krylov basis, l columns per block
  MatrixXd Ys(m, width);  // B P, block by block (double: the stopping test and the Ritz step need it)
  MatrixXd G(width, width);  // Ys^T Ys, grown block by block
  MatrixXf Y = gaussian(m, l, opt.seed), Xf, Z;
  MatrixXd X;
  int blocks = 0;
  double last_err = -1;
  while (blocks < max_blocks) {
    const Index used = Index(blocks) * l, w = used + l;
    product_bt(B, Y, Z);  // n x l
    step();
    X = Z.cast<double>();
    orthonormalize_against(P, used, X);
    P.middleCols(used, l) = X;
    Xf = X.cast<float>();
    Y.noalias() = B * Xf;  // m x l
    step();
    Ys.middleCols(used, l) = Y.cast<double>();
    ++blocks;
    if (blocks == max_blocks) break;
    // Error-driven stop: the rank-C error of the current basis, from the eigenvalues of
    // (B P)^T B P (in double: the residual is a small difference of large sums).
    G.block(0, used, w, l).noalias() = Ys.leftCols(w).transpose() * Ys.middleCols(used, l);
    G.block(used, 0, l, used) = G.block(0, used, used, l).transpose();
    Eigen::SelfAdjointEigenSolver<MatrixXd> es(G.topLeftCorner(w, w), Eigen::EigenvaluesOnly);
    const Index c = std::min<Index>(opt.max_rank, w);
    const double kept = es.eigenvalues().tail(c).cwiseMax(0.0).sum();
    const double err = r.total_energy > 0 ? std::sqrt(std::max(0.0, r.total_energy - kept) / r.total_energy) : 0;
    if (blocks >= 2 && last_err - err <= k_krylov_stop * err) break;
    last_err = err;
  }
  Y.resize(0, 0), Z.resize(0, 0), G.resize(0, 0);
  const Index w = Index(blocks) * l;
  // Ritz step: B P = Qy R (Householder, double), then the SVD of the small R.
  Eigen::HouseholderQR<MatrixXd> qr(Ys.leftCols(w));
  Ys.resize(0, 0);
  const MatrixXd R = qr.matrixQR().topRows(w).triangularView<Eigen::Upper>();
  Eigen::JacobiSVD<MatrixXd> svd(R, Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Eigen::VectorXd lambda = svd.singularValues().array().square();
  const int rank = choose_rank(lambda, r.total_energy, opt, r.data_rank_limit, r.target_reached);
  r.S = svd.singularValues().head(rank);
  r.kept_energy = lambda.head(rank).sum();
  MatrixXd Ur = MatrixXd::Zero(m, rank);
  Ur.topRows(w) = svd.matrixU().leftCols(rank);
  r.U = (qr.householderQ() * Ur).cast<float>();
  r.SxV = (P.leftCols(w) * (svd.matrixV().leftCols(rank) * r.S.asDiagonal())).cast<float>();
  r.iterations = blocks;
  if (opt.progress) opt.progress->finish();
  return r;
}

Result<SvdResult> randomized_svd(ConstMapF& B, const SvdOptions& opt) {
  return opt.scheme == RandomizedScheme::block_krylov ? krylov_svd(B, opt) : power_svd(B, opt);
}

}  // namespace

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

// From this size on top_eigenpairs asks LAPACK (dsyevd): Eigen's solver (unblocked Householder
// tridiagonalization and implicit QL) took minutes at k = 4096, LAPACK's divide and conquer
// seconds. Smaller matrices keep Eigen's solver, so every model of a smaller Gram matrix (every
// default setting) is what it was, bit for bit.
constexpr Index k_lapack_eigen_from = 1025;

namespace {

#ifdef BTFC_HAVE_OPENBLAS
// All eigenpairs by dsyevd, ascending; false when LAPACK reports a failure (then Eigen's solver runs).
bool lapack_eigen(const MatrixXd& G, Eigen::VectorXd& w, MatrixXd& A) {
  if (G.rows() > INT_MAX / 4) return false;
  const int n = int(G.rows());
  A = G;  // column-major, overwritten by the eigenvectors
  w.resize(n);
  int info = 0, lwork = -1, liwork = -1, iwork_query = 0;
  double work_query = 0;
  dsyevd_("V", "L", &n, A.data(), &n, w.data(), &work_query, &lwork, &iwork_query, &liwork, &info, 1, 1);
  if (info != 0) return false;
  lwork = int(work_query);
  liwork = iwork_query;
  std::vector<double> work(size_t(std::max(lwork, 1)));
  std::vector<int> iwork(size_t(std::max(liwork, 1)));
  dsyevd_("V", "L", &n, A.data(), &n, w.data(), work.data(), &lwork, iwork.data(), &liwork, &info, 1, 1);
  return info == 0 && w.allFinite();
}
#endif

}  // namespace

void top_eigenpairs(const MatrixXd& G, Index l, Eigen::VectorXd& lambda, MatrixXd& vecs) {
  const Index k = G.rows();
#ifdef BTFC_HAVE_OPENBLAS
  if (k >= k_lapack_eigen_from) {
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

Result<SvdResult> truncated_svd(const float* B, size_t m, size_t n, const SvdOptions& opt) {
  if (m == 0 || n == 0) return invalid_argument("SVD of an empty matrix");
  if (opt.max_rank < 1) return invalid_argument("SVD rank must be >= 1");
  ConstMapF map(B, Index(m), Index(n));
  SvdMethod method = opt.method;
  const size_t small = std::min(m, n);
  if (method == SvdMethod::automatic)
    method = small <= 1024 || (small <= k_exact_auto_max && size_t(opt.max_rank + opt.oversample) * 8 >= small) ? SvdMethod::exact
                                                                                                          : SvdMethod::randomized;
  // The randomized sketch cannot exceed the small side; then the exact path is both exact and cheap.
  if (method == SvdMethod::randomized && size_t(opt.max_rank) + size_t(opt.oversample) >= std::min(m, n))
    method = SvdMethod::exact;
  return method == SvdMethod::exact ? exact_svd(map, opt) : randomized_svd(map, opt);
}

ExactSvdReuse::ExactSvdReuse() {
  std::lock_guard<std::mutex> lock(g_reuse_mutex);
  ++g_reuse_scopes;
}

ExactSvdReuse::~ExactSvdReuse() {
  std::lock_guard<std::mutex> lock(g_reuse_mutex);
  if (--g_reuse_scopes == 0) g_reuse.clear();
}

size_t ExactSvdReuse::reuses() {
  std::lock_guard<std::mutex> lock(g_reuse_mutex);
  return g_reuses;
}

}  // namespace btfc
