// Streaming randomized SVD; see ooc_svd.h for the algorithm and the contracts.
#include "codecs/fmf/ooc_svd.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>

#include "codecs/fmf/ooc_pass.h"
#include "core/blas_env.h"
#include "core/thin_product.h"

namespace btfc::fmf {

using Eigen::Index;
using Eigen::MatrixXd;
using Eigen::MatrixXf;

// acc += Y (double += float), in parallel over columns: with the CLI's chunks (~3300 texels at
// UBO2003 size) a serial m x l add per chunk took a tenth of a pass. Element-wise: the result
// does not depend on the thread count.
static void add_into(Eigen::Map<MatrixXd> acc, const MatrixXf& Y) {
#pragma omp parallel for schedule(static)
  for (Index j = 0; j < Y.cols(); ++j) acc.col(j) += Y.col(j).cast<double>();
}

Result<SvdResult> streaming_svd(const ChunkSource& src, const std::vector<size_t>& chunks, const SvdOptions& opt, Collective& coll,
                                StreamStats* stats_out, int kept_blocks) {
  const size_t m = src.rows(), n = src.texels();
  if (m == 0 || n == 0) return invalid_argument("SVD of an empty matrix");
  if (opt.max_rank < 1) return invalid_argument("SVD rank must be >= 1");
  const Index l = Index(std::min<size_t>(std::min(m, n), size_t(opt.max_rank) + size_t(opt.oversample)));
  // The passes run btfc's OpenMP kernels; the small BLAS products between and within them (the
  // orthonormalisation, W^T W per chunk) would leave OpenBLAS's own threads spinning against
  // them for the 2 cores: 2.5-2.8 s instead of 2.2-2.3 s at rank 32, q 1, UBO2003 size.
  SingleThreadedBlas serial_blas;
  // Block Krylov on the rows side: blocks Q_1 = orth(B B^T Omega), Q_{b+1} = orth(B B^T Q_b) against
  // the kept ones, in P (m x kept l, double); at most q + 1 blocks, as in core. When fewer may be
  // kept (memory), a full P restarts from its Ritz vectors (below; kept 1: the power iteration).
  const int max_blocks = int(std::max<Index>(1, std::min<Index>(opt.power_iters + 1, std::min<Index>(Index(m), Index(n)) / l)));
  const int kept = kept_blocks > 0 ? std::min(kept_blocks, max_blocks) : max_blocks;
  const Index width = Index(kept) * l;
  const int total_passes = max_blocks + 1;  // at most: the error-driven stop may end earlier
  PassRunner run(src, chunks, coll, opt.progress, "fmf out-of-core SVD", total_passes);
  std::vector<double>& buf = run.sums();

  // Every pass sums its m x l block straight into the allreduce buffer (zeroed before the chunks,
  // ooc_pass.h): no second m x l copy in double.
  auto sum_of = [&]() { return Eigen::Map<MatrixXd>(buf.data(), Index(m), l); };
  // Pass 0: Y = B (B^T Omega), Omega on the rows as in core (svd.h, make_row_sketch: a sparse
  // sign sketch, so B^T Omega costs ~ a read of the chunk), and ||B||_F^2.
  double energy = 0;
  {
    const RowSketch sketch = make_row_sketch(m, l, opt);
    MatrixXf Z, Yf;
    auto sketch_pass = [&](size_t, const float* Bp, size_t k) {
      Z.resize(Index(k), l);
      row_sketch_product(Bp, k, sketch, Z, &energy);
      thin_product(Bp, m, k, Z, Yf);
      add_into(sum_of(), Yf);
    };
    BTFC_RETURN_IF_ERROR(run.pass(m * size_t(l) + 1, sketch_pass, [&](double* d) { d[m * size_t(l)] = energy; }));
    energy = buf[m * size_t(l)];
  }
  BTFC_RETURN_IF_ERROR(src.finish_first_pass(coll));
  MatrixXd P(Index(m), width);
  P.leftCols(l) = sum_of();
  orthonormalize_against(P, 0, P.leftCols(l));
  int blocks = 1, in_p = 1;  // blocks made, blocks in P
  // Passes 1..: Y = B B^T Q_b (one read, both products per chunk), then the error of the basis so
  // far from its Gram matrix P^T B B^T P, whose last block column is P^T Y (no extra pass).
  // W^T = B^T P of the owned chunks (n_c x width each), filled block by block: pass b's first
  // product Z = B_c^T Q_b is its block column, so the last pass only adds the newest block's.
  std::vector<MatrixXf> wt(src.num_chunks());
  auto wt_block = [&](size_t c, size_t k, Index at) {
    if (wt[c].rows() != Index(k)) wt[c].resize(Index(k), width);
    return wt[c].middleCols(at, l);
  };
  MatrixXd K = MatrixXd::Zero(width, width);
  double last_err = -1;
  while (blocks < max_blocks) {
    const Index used = Index(in_p - 1) * l, w = used + l;
    const MatrixXf Q = P.middleCols(used, l).cast<float>();
    MatrixXf Yf;
    auto power = [&](size_t c, const float* Bp, size_t k) {
      auto Z = wt_block(c, k, used);
      transposed_product(Bp, m, k, Q, Z);
      thin_product(Bp, m, k, Z, Yf);
      add_into(sum_of(), Yf);
    };
    BTFC_RETURN_IF_ERROR(run.pass(m * size_t(l), power, [](double*) {}));
    const auto Y = sum_of();
    K.block(0, used, w, l).noalias() = P.leftCols(w).transpose() * Y;
    K.block(used, 0, l, used) = K.block(0, used, used, l).transpose();
    // The in-core stop (svd.cpp): a block that gained at most k_krylov_stop of the error ends
    // the iteration. The next block, orth(Y), costs no pass and still joins the basis.
    const bool full = in_p == kept;
    Eigen::SelfAdjointEigenSolver<MatrixXd> es(K.topLeftCorner(w, w), full ? Eigen::ComputeEigenvectors : Eigen::EigenvaluesOnly);
    const double got = es.eigenvalues().tail(std::min<Index>(opt.max_rank, w)).cwiseMax(0.0).sum();
    const double err = energy > 0 ? std::sqrt(std::max(0.0, energy - got) / energy) : 0;
    const bool stop = blocks >= 2 && last_err - err <= k_krylov_stop * err;
    last_err = err;
    if (full) {
      // The window is full: restart from the best r = (kept - 1) l directions of span(P), its Ritz
      // vectors P E (a thick restart; dropping the oldest block instead would drop the dominant
      // directions, which the later blocks are orthogonal to). Their Gram matrix is diagonal.
      const Index r = width - l;
      const MatrixXd E = es.eigenvectors().rightCols(r);
      for (Index i = 0; i < Index(m); i += 1024) {
        const Index h = std::min<Index>(1024, Index(m) - i);
        const MatrixXd rows = P.middleRows(i, h) * E;
        P.block(i, 0, h, r) = rows;
      }
      for (size_t c : chunks) wt[c].leftCols(r) = (wt[c] * E.cast<float>()).eval();  // B^T (P E) = (B^T P) E
      K.topLeftCorner(r, r) = es.eigenvalues().tail(r).asDiagonal();
      --in_p;
    }
    const Index at = Index(in_p) * l;
    P.middleCols(at, l) = Y;
    orthonormalize_against(P, at, P.middleCols(at, l));
    ++blocks, ++in_p;
    if (stop) break;
  }
  K.resize(0, 0);
  const Index w = Index(in_p) * l;
  // Last pass: the newest block's columns of W^T = B^T P, and W W^T (w x w).
  MatrixXd G = MatrixXd::Zero(w, w);
  {
    const Index at = w - l;
    const MatrixXf Q = P.middleCols(at, l).cast<float>();
    auto project = [&](size_t c, const float* Bp, size_t k) {
      auto Z = wt_block(c, k, at);
      transposed_product(Bp, m, k, Q, Z);
      const auto W = wt[c].leftCols(w);
      G += (W.transpose() * W).cast<double>();
    };
    BTFC_RETURN_IF_ERROR(run.pass(size_t(w * w), project, [&](double* d) { std::copy(G.data(), G.data() + G.size(), d); }));
  }
  G = Eigen::Map<MatrixXd>(buf.data(), w, w);
  run.release();

  MatrixXd E;
  SvdResult r = spectrum_of(G, w, energy, opt, "randomized (streamed)", E);
  r.iterations = blocks;
  const Index rank = r.S.size();
  const MatrixXd Ek = E.leftCols(rank);
  r.U = (P.leftCols(w) * Ek).cast<float>();
  // SxV rows of the owned texels, summed (disjoint rows: exact) into process 0.
  MatrixXfR sxv = MatrixXfR::Zero(Index(n), rank);
  const MatrixXf Ekf = Ek.cast<float>();
  for (size_t c : chunks) sxv.middleRows(Index(src.chunk_first(c)), wt[c].rows()) = wt[c].leftCols(w) * Ekf;
  wt.clear();
  BTFC_RETURN_IF_ERROR(run.finish(r, sxv, stats_out));
  return r;
}

}  // namespace btfc::fmf
