// Truncated SVD of a column-major float matrix B (m rows x n columns): numerics shared by fmf,
// lpyr and lpca (codecs do not include each other).
//
// Two paths:
//  - exact: eigen-decomposition, in double, of the smaller Gram matrix (B B^T when m <= n, else
//    B^T B). The kept components are then exactly the top singular triplets up to double
//    round-off, so the rank-C error equals the Eckart-Young optimum sum_{i>C} sigma_i^2.
//    Cost min(m,n)^2 max(m,n) for the Gram matrix plus min(m,n)^3 for its eigendecomposition
//    (LAPACK's dsyevd from k = 1025 on when built with OpenBLAS): right for matrices with one
//    small side (one view, few texels), and for large ranks of a side up to 4096, where it costs
//    the same at every rank and less than a sketch of 1/8 of that side.
//  - randomized, two schemes over the same passes (each pass over B is one float GEMM of width
//    l = C + oversample through Eigen and OpenBLAS, multi-threaded; B is never copied):
//    block_krylov (default): randomized block Krylov (Musco and Musco 2015) on the rows side, up
//    to q + 1 blocks kept side by side (for q >= 2 the first of l columns, the later ones of
//    min(l, C), started from the first block's top Ritz vectors), two passes per block, no final
//    pass (svd.cpp, krylov_svd), stopping early once a block no longer improves the rank-C
//    error; at most 2q + 2 passes: a sparse sign sketch of B's columns (one add per element;
//    SvdOptions::sparse_sketch), then q + 1 passes B^T Q and q passes B X.
//    power: Halko, Martinsson, Tropp 2011, Alg. 4.4 with re-orthonormalised power iterations:
//    sketch Y = B Omega, q power iterations, Q = orth(Y), then the small SVD of Q^T B; 2q + 2
//    passes. The out-of-core path (codecs/fmf/ooc_svd.h) streams block Krylov on the rows side.
//
// Output: U (m x C, orthonormal columns) and SxV = B^T U (n x C, the right singular vectors
// already multiplied by the singular values, seed 000 section 4: V := V Sigma), so that
// B ~ U SxV^T is the orthogonal projection of B onto span(U). Components whose singular value
// is below 1e-6 * sigma_max (float noise) are dropped and the clamp is reported; at least one
// component is always kept so shapes stay non-empty (all-zero input -> one zero component).
#pragma once
#include <Eigen/Core>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "core/progress.h"
#include "core/sparse_sketch.h"
#include "core/status.h"

namespace btfc {

// automatic: exact when the small side is <= 1024, or <= k_exact_auto_max and the sketch
// (rank + oversample) would be at least 1/8 of it; else randomized.
enum class SvdMethod { automatic, exact, randomized };
enum class RandomizedScheme { block_krylov, power };
constexpr size_t k_exact_auto_max = 4096;

struct SvdOptions {
  int max_rank = 32;
  double target_rel_error = 0;  // > 0: smallest rank <= max_rank with ||B - B'||/||B|| <= target
  SvdMethod method = SvdMethod::automatic;
  int oversample = 16;
  int power_iters = 4;
  uint64_t seed = 1;
  RandomizedScheme scheme = RandomizedScheme::block_krylov;
  // block_krylov: the first block from a sparse sign sketch (core/sparse_sketch.h) when B has at
  // least 4 s columns (s = 4 l rounded up to 128, at least 256; l = rank + oversample <= 256): a
  // pass at memory speed instead of a GEMM. false: a dense Gaussian test matrix. (The streamed
  // SVD, ooc_svd.h, sketches B's rows by the same rule.)
  bool sparse_sketch = true;
  // The streamed SVD (codecs/fmf/ooc_svd.h) with a sparse first block: its chunks' B S summed in
  // one m x s buffer and multiplied by G once (column_sketch_sums), or (false) each chunk's
  // B S G on its own, without the buffer (the out-of-core plan's choice under a tight memory
  // limit). Unused in core.
  bool sketch_sums = true;
  // Inside a RandomizedSvdReuse scope (below): a randomized factorization may be served as the
  // leading max_rank components of a larger randomized one of the same matrix. For callers whose
  // models at different ranks are nested truncations anyway (fmf's rank), not for target_rel_error.
  bool truncation_ok = false;
  Progress* progress = nullptr;
};

using MatrixXfR = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

struct SvdResult {
  MatrixXfR U;              // m x C, row-major: one (light, view, colour) row's components contiguous
  MatrixXfR SxV;            // n x C, row-major: one texel's components contiguous
  Eigen::VectorXd S;        // C singular values, descending
  double total_energy = 0;  // ||B||_F^2
  double kept_energy = 0;   // sum of kept sigma^2
  std::string method;       // "exact" or "randomized"
  int requested_rank = 0;
  int data_rank_limit = 0;  // min(m, n, numerical rank seen)
  bool target_reached = true;
  int iterations = 0;       // randomized block_krylov: blocks computed (2 passes each); else 0
  bool sparse_start = false;  // block_krylov: the first block came from the sparse sign sketch
  // Estimated relative Frobenius error sqrt(max(0, total - kept) / total).
  double rel_error_estimate() const;
};

// The top `l` eigenpairs (eigenvalues descending, clamped at 0) of a symmetric PSD matrix, in
// double; l <= G.rows(). Shared by the exact SVD path and lpca's per-cluster PCA.
// From `lapack_from` rows on it asks LAPACK's divide and conquer (dsyevd, where btfc links
// OpenBLAS); below, Eigen's solver (unblocked Householder tridiagonalization and implicit QL:
// minutes at 4096, ~0.5 s at 768-1024 where dsyevd takes 0.1-0.2 s). The default keeps Eigen's
// solver, whose bits lpca's models and the randomized paths' small Rayleigh-Ritz steps have
// always had; the exact SVD (in core and streamed, and so lpyr's small levels) takes LAPACK from
// k_exact_lapack_eigen_from on.
constexpr Eigen::Index k_lapack_eigen_from = 1025;
constexpr Eigen::Index k_exact_lapack_eigen_from = 128;
void top_eigenpairs(const Eigen::MatrixXd& G, Eigen::Index l, Eigen::VectorXd& lambda, Eigen::MatrixXd& vecs,
                    Eigen::Index lapack_from = k_lapack_eigen_from);
// The eigenvalues (and with `vecs`, the eigenvectors) of a symmetric matrix, ascending as
// Eigen's solver gives them, by the same rule: Eigen's solver below `lapack_from` rows (the bits
// the Krylov iterations' stopping tests and restarts have always had), LAPACK's dsyevd from there
// on. Why: the error-driven stop of a rank-1024 randomized SVD solves a 2080-5200 row Gram matrix
// per block, and Eigen's unblocked solver took minutes of it (docs/benchmarks.md).
void symmetric_eigen(const Eigen::MatrixXd& G, Eigen::VectorXd& ascending, Eigen::MatrixXd* vecs,
                     Eigen::Index lapack_from = k_lapack_eigen_from);

// How many columns (or rows) of length `len` the exact path converts to double at a time for
// its Gram sums and projections: at most 4096 and at most 32 MiB of double. In core and streamed.
Eigen::Index exact_double_block(Eigen::Index len);

// How many of the descending eigenvalues `lambda` (sigma^2) of a matrix with energy `total`
// (||B||_F^2) to keep: at most opt.max_rank and the numerical rank (sigma > 1e-6 sigma_max),
// with target_rel_error the smallest such rank reaching it; at least 1. Sets data_rank and
// reached. Shared by truncated_svd and the out-of-core path (ooc_svd.h).
int choose_rank(const Eigen::VectorXd& lambda, double total, const SvdOptions& opt, int& data_rank, bool& reached);


// X := an orthonormal basis of X's columns that is orthogonal to the first `used` columns of P
// (orthonormal), in double: block Gram-Schmidt and Cholesky QR, twice, Householder where a
// round is ill-conditioned; columns that lie in span(P) to double precision are replaced by
// pseudo-random ones (krylov_blocks.cpp). The block step of both block Krylov SVDs (both on the
// rows side).
void orthonormalize_against(const Eigen::Ref<const Eigen::MatrixXd>& P, Eigen::Index used, Eigen::Ref<Eigen::MatrixXd> X);
// Columns [from, w) of Wt^T Wt (w x (w - from), Wt n x w), in double: Wt's rows converted by
// blocks of at most ~4 MB, in at most 16 fixed groups on the OpenMP threads summed in order (the
// same bits at any thread count). Both block Krylov SVDs' W W^T, the Ritz step's matrix (a small
// difference of large sums: float would lose the tail of the spectrum): in core a block's new
// columns, streamed a chunk's part.
Eigen::MatrixXd gram_columns(const Eigen::Ref<const Eigen::MatrixXf>& Wt, Eigen::Index from);

// A rows x cols Gaussian matrix (N(0, 1) floats) from a seeded engine, Box-Muller on raw 64-bit
// draws so the numbers do not depend on the standard library's distributions: the sketch's G and
// the power iterations' start (krylov_blocks.cpp).
Eigen::MatrixXf gaussian_matrix(Eigen::Index rows, Eigen::Index cols, uint64_t seed);

// Both block Krylov SVDs' first block (in core, svd.cpp; streamed, ooc_svd.h), on B's n columns:
// Pi = S G, a sparse sign sketch S (n x s, one +-1 per column of B) and a Gaussian G (s x l),
// when opt.sparse_sketch and n >= 4 s, s = 4 l rounded up to a multiple of 128, 256 <= s <= 1024;
// else a dense Gaussian Pi (n x l) in G and S.s == 0. Deterministic for opt.seed.
struct Sketch {
  SparseSign S;
  Eigen::MatrixXf G;
  bool sparse() const { return S.s > 0; }
};
Sketch make_column_sketch(size_t n, Eigen::Index l, const SvdOptions& opt);
// Y = B Pi (m x l, sized by the caller), setting *energy = ||B||_F^2 when given (B m x n
// column-major). A chunk of B's columns, texels [first, first + n) of the sketch's, gives its
// part of the sum. `scratch`, when given, holds the sketch's row blocks from call to call (fresh
// pages cost more than the pass on some VMs). `ldb`: B's leading dimension (0: m).
void column_sketch_product(const float* B, size_t m, size_t n, const Sketch& sketch, Eigen::Ref<Eigen::MatrixXf> Y,
                           double* energy = nullptr, size_t first = 0, std::vector<float>* scratch = nullptr, size_t ldb = 0);
// The scratch column_sketch_product takes for B m x n at l columns: at most 16 MiB and at most the
// n l floats of a dense Pi (0 when dense: Pi itself is then n x l).
size_t column_sketch_bytes(size_t m, size_t n, Eigen::Index l);
// The same first pass in two steps, for a stream of chunks (sparse sketches only): each chunk's
// B S added into W (m x s, column-major, zeroed by the caller; texels [first, first + n) of the
// sketch's), *energy += its ||B||_F^2; then once Y = W G. One W G for the whole stream instead of
// one per chunk (2 m s l flops each: a fifth of the streamed pass at UBO2003 size), for
// column_sketch_sums_bytes(m, n, l) bytes of W (0: the sketch is dense, use
// column_sketch_product). With `segment` > 0: B's rows are matrices of `segment` rows stacked,
// energy[k] += matrix k's ||.||_F^2 (sparse_sign_columns).
void column_sketch_sums(const float* B, size_t m, size_t n, const Sketch& sketch, float* W, double* energy, size_t first,
                        size_t ldb = 0, size_t segment = 0);
// ldw: W's leading dimension (0: m), e.g. one matrix's rows of a stacked sum.
void column_sketch_finish(const float* W, size_t m, const Sketch& sketch, Eigen::Ref<Eigen::MatrixXf> Y, size_t ldw = 0);
size_t column_sketch_sums_bytes(size_t m, size_t n, Eigen::Index l);

// Block Krylov's error-driven stop: after at least two blocks, stop once a block improved the
// rank-C error by at most this fraction of itself (the remaining gap to the optimum is then a
// fraction of that).
constexpr double k_krylov_stop = 2e-3;

// The width of block Krylov's blocks after the first (of l columns) for rank C and up to
// max_blocks blocks: min(l, C) from three blocks on, else l (svd.cpp krylov_svd), in core and
// streamed alike.
constexpr Eigen::Index later_krylov_width(int max_blocks, Eigen::Index l, Eigen::Index C) { return max_blocks >= 3 && C < l ? C : l; }

// B is column-major with leading dimension m. Fails on m == 0 or n == 0. The randomized method
// fails with corrupt_data when B holds a NaN or an infinity, found in its first pass before any
// product: B's squared norm, summed there in double from every value, is finite exactly when
// every value is (a float squared is at most 1.2e77). A caller may leave its own input check to
// that pass (svd_checks_finite) and name the value after such a failure (Btf::check_finite).
// (A call served from a kept factorization, RandomizedSvdReuse, runs no pass: it factorized the
// same matrix before.) The exact method does not check.
Result<SvdResult> truncated_svd(const float* B, size_t m, size_t n, const SvdOptions& opt);
// Whether truncated_svd of an m x n matrix with `opt` runs the randomized method's check above.
bool svd_checks_finite(size_t m, size_t n, const SvdOptions& opt);
// The method truncated_svd runs for an m x n matrix: opt.method with automatic resolved (above),
// and exact whenever rank + oversample reaches the small side.
SvdMethod resolved_method(size_t m, size_t n, const SvdOptions& opt);

// While one of these is alive, the exact path keeps the eigendecompositions of the Gram matrices
// it computes (the last three) and reuses one for a matrix of the same shape and content (a
// 64-bit fingerprint of every value): a byte-budget search (codecs/target.h) probes fmf at many
// ranks of one matrix, and the decomposition, which does not depend on the rank, is most of
// each probe's cost. With each it keeps the projection's panels computed so far (below), so a
// probe projects only the panels its rank adds. Results are the same with or without it. Not for
// concurrent searches.
class ExactSvdReuse {
 public:
  ExactSvdReuse();
  ~ExactSvdReuse();
  ExactSvdReuse(const ExactSvdReuse&) = delete;
  ExactSvdReuse& operator=(const ExactSvdReuse&) = delete;
  static size_t reuses();  // how many exact SVDs were served from it (tests)
  // How many projection columns the exact path has computed, in or out of a scope (tests): the
  // kept decompositions keep their projections too, by panels of 32 columns whose bits do not
  // depend on the rank asked for, so a smaller rank takes leading columns and a larger one adds
  // panels, each with the bits of its rank encoded alone.
  static size_t projected_columns();
};

// While one of these is alive (a byte-budget search over fmf's rank, codecs/target.cpp), a
// randomized truncated_svd with opt.truncation_ok and max_rank r <= max_rank is served from one
// randomized SVD of the same matrix (fingerprint, shape and options) at a rank R >= r, truncated
// to its leading r components. When the kept one is smaller (or of another matrix), a new one
// at R = min(max_rank, twice the larger of r and the kept rank, rounded up to 64) replaces it:
// a search computes a few factorizations of geometrically growing rank, not one per probe.
// Why: each probe of a budget search was a whole randomized SVD, so a budget search could not
// afford the large ranks that quantized factors make affordable (docs/benchmarks.md). The
// leading components of a rank-R factorization come from a larger sketch (more oversampling) and
// are as accurate as a rank-r one's or more, but not the same bits: a model from a search can
// differ from the same spec encoded alone, within the randomized SVD's accuracy (tests compare
// both). Holds one factorization, (m + n) R floats. Inside an ExactSvdReuse scope as well, and
// with the automatic method, a request that the kept one does not cover takes the exact path
// instead when that scope holds the matrix's Gram eigenpairs already, or when R would be cut
// below the rule above by the randomized path's range (a small side of at most 4096, where the
// exact path serves every rank at one cost); the input is still checked for non-finite values.
// Not for concurrent searches.
class RandomizedSvdReuse {
 public:
  explicit RandomizedSvdReuse(int max_rank);
  ~RandomizedSvdReuse();
  RandomizedSvdReuse(const RandomizedSvdReuse&) = delete;
  RandomizedSvdReuse& operator=(const RandomizedSvdReuse&) = delete;
  static bool active();      // a scope is alive
  // Whether serve_set(key, ranks, randomized_at, ...) would compute a set at a rank the
  // randomized path cannot grow to (randomized_at caps it below the growth rule's rank), inside
  // both a RandomizedSvdReuse and an ExactSvdReuse scope. A caller that can factorize its
  // matrices exactly then should (fmf's color=dfmf channels): the exact path keeps their Gram
  // eigenpairs and serves every later rank, where a randomized set at the capped rank costs about
  // as much and serves fewer (truncated_svd does the same for one matrix).
  static bool grows_past_randomized(uint64_t key, const std::vector<int>& ranks, const std::function<bool(int)>& randomized_at);
  static size_t computed();  // randomized SVDs the scopes computed (tests)
  static size_t served();    // truncations they served, computed ones included (tests)

  // Several matrices factorized together outside truncated_svd (fmf's color=dfmf stream: its
  // three channel matrices in one pass over the data, codecs/fmf). Inside a scope, the leading
  // ranks[i] components of the kept set of the same key (the caller's fingerprint of its data
  // and options) when each kept matrix was computed at ranks[i] or more; else compute() at grown
  // ranks (per matrix as above: a rank that is not covered grows to twice itself or the kept
  // one, rounded up to 64, at most the scope's rank and at most the largest rank that
  // randomized_at accepts; a covered one keeps the kept rank), kept for the next request. Why:
  // a dfmf byte-budget search on a large BTF encoded every probe from scratch (minutes for one
  // search at UBO2003 size). Outside a scope, compute(ranks) alone. `extra` is the caller's
  // figure for the set, kept with it (dfmf: the clamped values' count). One set kept per scope;
  // it counts in computed() / served() as one factorization. Not for concurrent searches.
  struct Set {
    std::vector<SvdResult> r;
    double extra = 0;
  };
  static Result<Set> serve_set(uint64_t key, const std::vector<int>& ranks, const std::function<bool(int)>& randomized_at,
                               const std::function<Result<Set>(const std::vector<int>&)>& compute);
};

// A 64-bit fingerprint of n floats (their bits), in parallel blocks (~0.05 s for 300 MB): the
// reuse scopes' key for "the same data".
uint64_t data_fingerprint(const float* data, size_t n);

}  // namespace btfc
