// Streaming exact SVD through the rows x rows Gram matrix; see ooc_svd.h for the contract.
//
// The in-core exact path (svd.cpp, exact_svd) eigendecomposes G = B B^T in double and projects
// SxV = B^T U. Both steps only ever need one column block of B at a time, so out of core they
// become two passes: pass 1 sums G and ||B||_F^2 over the chunks (one collective sum of G's lower
// triangle), pass 2 computes the chunk's rows of SxV = B_c^T U. The eigen-solver and the rank
// choice are the in-core ones (top_eigenpairs, choose_rank), so the result equals exact_svd's up
// to float rounding of the SxV GEMM.
#include <Eigen/Dense>
#include <algorithm>

#include "codecs/fmf/ooc_pass.h"
#include "codecs/fmf/ooc_svd.h"

namespace btfc::fmf {
namespace {

using Eigen::Index;
using Eigen::MatrixXd;
using Eigen::MatrixXf;

}  // namespace

uint64_t streaming_exact_bytes(uint64_t m) {
  // G, LAPACK's copy of it (overwritten by the eigenvectors), dsyevd's workspace (2 m^2 + 6 m)
  // and the sorted copy top_eigenpairs returns are alive together (5 m^2 doubles; Eigen's solver,
  // below k_exact_lapack_eigen_from, holds less; the sum buffer, half a Gram, is freed before the
  // solver runs), plus one double column block.
  return (5 * m * m + 6 * m) * 8 + m * uint64_t(exact_double_block(m)) * 8;
}

Result<SvdResult> streaming_exact_svd(const ChunkSource& src, const std::vector<size_t>& chunks, const SvdOptions& opt, Collective& coll,
                                      StreamStats* stats_out) {
  const size_t m = src.rows(), n = src.texels();
  if (m == 0 || n == 0) return invalid_argument("SVD of an empty matrix");
  if (opt.max_rank < 1) return invalid_argument("SVD rank must be >= 1");
  PassRunner run(src, chunks, coll, opt.progress, "fmf out-of-core exact SVD", 2);
  std::vector<double>& buf = run.sums();
  const Index M = Index(m), block = exact_double_block(m);
  const size_t tri = m * (m + 1) / 2;  // the lower triangle is what the processes sum

  // Pass 1: G = sum_c B_c B_c^T (lower triangle) and ||B||_F^2, in double.
  MatrixXd G = MatrixXd::Zero(M, M);
  double energy = 0;
  {
    MatrixXd Bd;
    auto gram = [&](size_t, const float* Bp, size_t k) {
      Eigen::Map<const MatrixXf> B(Bp, M, Index(k));
      for (Index j0 = 0; j0 < Index(k); j0 += block) {
        Bd = B.middleCols(j0, std::min(block, Index(k) - j0)).cast<double>();
        energy += Bd.squaredNorm();
        G.selfadjointView<Eigen::Lower>().rankUpdate(Bd);
      }
    };
    BTFC_RETURN_IF_ERROR(run.pass(tri + 1, gram, [&](double* d) {
      for (Index j = 0; j < M; ++j) d = std::copy(G.col(j).data() + j, G.col(j).data() + M, d);
      *d = energy;
    }));
    const double* d = buf.data();
    for (Index j = 0; j < M; ++j)
      for (Index i = j; i < M; ++i, ++d) G(i, j) = G(j, i) = *d;
    energy = buf[tri];
    std::vector<double>().swap(buf);  // before the solver: keeps the peak at 3 m^2 doubles
  }
  BTFC_RETURN_IF_ERROR(src.finish_first_pass(coll));  // e.g. a raw .btfc's CRC, joined over processes

  MatrixXd E;
  SvdResult r = spectrum_of(G, M, energy, opt, "exact (streamed)", E, k_exact_lapack_eigen_from);
  G.resize(0, 0);
  const Index rank = r.S.size();
  r.U = E.leftCols(rank).cast<float>();
  E.resize(0, 0);

  // Pass 2: the owned rows of SxV = B^T U (the projection, as in core), summed (disjoint rows:
  // exact) into process 0. The pass's collective sum carries only the error flag.
  MatrixXfR sxv = MatrixXfR::Zero(Index(n), rank);
  const MatrixXf Uf = r.U;
  auto project = [&](size_t c, const float* Bp, size_t k) {
    Eigen::Map<const MatrixXf> B(Bp, M, Index(k));
    sxv.middleRows(Index(src.chunk_first(c)), Index(k)).noalias() = B.transpose() * Uf;
  };
  BTFC_RETURN_IF_ERROR(run.pass(0, project, [](double*) {}));
  run.release();
  BTFC_RETURN_IF_ERROR(run.finish(r, sxv, stats_out));
  return r;
}

}  // namespace btfc::fmf
