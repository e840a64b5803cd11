// Streaming randomized SVD; see ooc_svd.h for the algorithm and the contracts.
#include "codecs/fmf/ooc_svd.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <optional>
#include <vector>

#include "codecs/fmf/ooc_pass.h"
#include "core/blas_env.h"
#include "core/memory.h"
#include "core/thin_product.h"

namespace btfc::fmf {

using Eigen::Index;
using Eigen::MatrixXd;
using Eigen::MatrixXf;

namespace {

// One factorization's block Krylov iteration (ooc_svd.h), driven pass by pass by the stream
// loop below: begin() before a pass, slice() on every part of every owned chunk, end_chunk()
// after a chunk, pack() / end() after the pass. Several run side by side in streaming_svds.
class Krylov {
 public:
  enum class Phase { sketch, power, project, done };

  Krylov(size_t m, size_t n, size_t num_chunks, const SvdOptions& opt, int kept_blocks)
      : m_m(m), m_opt(opt), m_l(Index(std::min<size_t>(std::min(m, n), size_t(opt.max_rank) + size_t(opt.oversample)))), m_wt(num_chunks) {
    m_max_blocks = int(std::max<Index>(1, std::min<Index>(opt.power_iters + 1, std::min<Index>(Index(m), Index(n)) / m_l)));
    m_kept = kept_blocks > 0 ? std::min(kept_blocks, m_max_blocks) : m_max_blocks;
    m_lk = later_krylov_width(m_max_blocks, m_l, opt.max_rank);
    m_bw = m_l;
    m_width = m_l + Index(m_kept - 1) * m_lk;
    m_sketch = make_column_sketch(n, m_l, opt);
  }
  int max_passes() const { return m_max_blocks + 1; }  // at most: the error-driven stop may end earlier
  Phase phase() const { return m_phase; }
  // After the first pass, before end(): whether the matrix's squared norm in the global sums is
  // finite, i.e. every value is (streaming_svds' input check, ooc_svd.h).
  bool finite_energy(const double* sums) const { return m_phase != Phase::sketch || std::isfinite(sums[m_m * size_t(m_bw)]); }
  // The sparse sketch this pass sums (W += B S over the chunks, Y = W G once), else null.
  const Sketch* summed_sketch() const {
    return m_phase == Phase::sketch && m_sketch.sparse() && m_opt.sketch_sums ? &m_sketch : nullptr;
  }
  // This pass's sums are the m rows at W (leading dimension ldw: one matrix's rows of a sum over
  // stacked matrices, held by the caller until pack()), its ||B||^2 `energy`: instead of slice()
  // on every part (streaming_svds).
  void use_sketch_sums(const float* W, size_t ldw, double energy) { m_sums_at = W, m_sums_ld = ldw, m_energy += energy; }
  // Doubles this pass sums over the processes: Y (m x the block's width; the first pass adds
  // ||B||_F^2), or G.
  size_t payload() const { return m_phase == Phase::project ? size_t(m_w * m_w) : m_m * size_t(m_bw) + (m_phase == Phase::sketch ? 1 : 0); }

  void begin() {
    if (m_phase == Phase::power) m_q.emplace(m_P.middleCols(m_at, m_bw).cast<float>());
    if (m_phase == Phase::project) {
      m_w = m_at + m_bw;
      m_q.emplace(m_P.middleCols(m_at, m_bw).cast<float>());
      m_G = MatrixXd::Zero(m_w, m_w);
    }
  }

  // Columns [o, o + k) of owned chunk c (count texels in all, the first of them texel `first`
  // of B), B: m x k, leading dimension ldb. Every pass sums its m x l block straight into `sums` (zeroed before the
  // chunks, ooc_pass.h): no second m x l copy in double.
  void slice(size_t c, size_t count, size_t first, size_t o, const float* B, size_t k, size_t ldb, double* sums) {
    auto acc = Eigen::Map<MatrixXd>(sums, Index(m_m), m_bw);
    switch (m_phase) {
      case Phase::sketch: {  // Y = B Pi: the chunk's part, through the sparse sign sketch ~ a read
        if (m_sketch.sparse() && m_opt.sketch_sums) {  // W += B S here, Y = W G once, in pack()
          if (m_w_sums.empty()) m_w_sums.assign(m_m * m_sketch.S.s, 0.0f), m_sums_at = m_w_sums.data(), m_sums_ld = m_m;
          column_sketch_sums(B, m_m, k, m_sketch, m_w_sums.data(), &m_energy, first + o, ldb);
          break;
        }
        double e = 0;
        m_y.resize(Index(m_m), m_l);
        column_sketch_product(B, m_m, k, m_sketch, m_y, &e, first + o, &m_scratch, ldb);
        m_energy += e;
        add_into(acc, m_y);
        break;
      }
      case Phase::power: {  // Y = B B^T Q_b; Z = B^T Q_b is block b of W^T, kept
        auto Z = wt_block(c, count).middleRows(Index(o), Index(k));
        transposed_product(B, m_m, k, *m_q, Z, nullptr, ldb);
        thin_product(B, m_m, k, Z, m_y, ldb);
        add_into(acc, m_y);
        break;
      }
      case Phase::project: {  // the newest block's B^T Q completes W^T
        auto Z = wt_block(c, count).middleRows(Index(o), Index(k));
        transposed_product(B, m_m, k, *m_q, Z, nullptr, ldb);
        break;
      }
      case Phase::done:
        break;
    }
  }
  void end_chunk(size_t c) {
    if (m_phase != Phase::project) return;
    m_G += gram_columns(m_wt[c].leftCols(m_w), 0);
  }
  void pack(double* sums) {
    if (m_phase == Phase::sketch && m_sums_at) {  // this process's chunks: Y = (sum of B_c S_c) G
      m_y.resize(Index(m_m), m_l);
      column_sketch_finish(m_sums_at, m_m, m_sketch, m_y, m_sums_ld);
      add_into(Eigen::Map<MatrixXd>(sums, Index(m_m), m_l), m_y);
      std::vector<float>().swap(m_w_sums);
      m_sums_at = nullptr;
    }
    if (m_phase == Phase::sketch) sums[m_m * size_t(m_l)] = m_energy;
    if (m_phase == Phase::project) std::copy(m_G.data(), m_G.data() + m_G.size(), sums);
  }

  // After the pass, with the global sums.
  void end(const double* sums) {
    const auto Y = Eigen::Map<const MatrixXd>(sums, Index(m_m), m_bw);
    if (m_phase == Phase::sketch) {
      m_energy = sums[m_m * size_t(m_l)];
      m_sketch = Sketch{};
      std::vector<float>().swap(m_scratch);
      m_P.resize(Index(m_m), m_width);
      m_P.leftCols(m_l) = Y;
      orthonormalize_against(m_P, 0, m_P.leftCols(m_l));
      m_blocks = 1;
      m_at = 0;
      m_K = MatrixXd::Zero(m_width, m_width);
      m_phase = m_blocks < m_max_blocks ? Phase::power : Phase::project;
      return;
    }
    if (m_phase == Phase::project) {
      m_G = Eigen::Map<const MatrixXd>(sums, m_w, m_w);
      m_phase = Phase::done;
      return;
    }
    // A power pass: the error of the basis so far from its Gram matrix P^T B B^T P, whose last
    // block column is P^T Y (no extra pass).
    const Index used = m_at, w = used + m_bw;
    m_K.block(0, used, w, m_bw).noalias() = m_P.leftCols(w).transpose() * Y;
    m_K.block(used, 0, m_bw, used) = m_K.block(0, used, used, m_bw).transpose();
    // The in-core stop (svd.cpp): a block that gained at most k_krylov_stop of the error ends
    // the iteration. The next block, orth(Y), costs no pass and still joins the basis.
    const bool full = w + m_lk > m_width;
    // The first block, wider than the later ones: the next starts from B B^T Q_1 E = Y E, E the
    // top m_lk eigenvectors of Q_1^T B B^T Q_1 (its top Ritz vectors, as in core: svd.cpp).
    const bool select = m_bw > m_lk;
    Eigen::VectorXd ev;
    MatrixXd evecs;
    symmetric_eigen(m_K.topLeftCorner(w, w), ev, full || select ? &evecs : nullptr);
    const double got = ev.tail(std::min<Index>(m_opt.max_rank, w)).cwiseMax(0.0).sum();
    const double err = m_energy > 0 ? std::sqrt(std::max(0.0, m_energy - got) / m_energy) : 0;
    const bool stop = m_blocks >= 2 && m_last_err - err <= k_krylov_stop * err;
    m_last_err = err;
    Index at = w;
    if (full) {
      // The basis is full: restart from its best r = width - lk directions, its Ritz vectors
      // P E (a thick restart; dropping the oldest block instead would drop the dominant
      // directions, which the later blocks are orthogonal to). Their Gram matrix is diagonal.
      const Index r = m_width - m_lk;
      const MatrixXd E = evecs.rightCols(r);
      for (Index i = 0; i < Index(m_m); i += 1024) {
        const Index h = std::min<Index>(1024, Index(m_m) - i);
        const MatrixXd rows = m_P.middleRows(i, h).leftCols(w) * E;
        m_P.block(i, 0, h, r) = rows;
      }
      const MatrixXf Ef = E.cast<float>();
      for (MatrixXf& wt : m_wt)
        if (wt.size()) wt.leftCols(r) = (wt.leftCols(w) * Ef).eval();  // B^T (P E) = (B^T P) E
      m_K.topLeftCorner(r, r) = ev.tail(r).asDiagonal();
      at = r;
    }
    if (select)  // Y and evecs are the pass's own: the restart above changed neither
      m_P.middleCols(at, m_lk) = Y * evecs.rightCols(m_lk);
    else
      m_P.middleCols(at, m_lk) = Y;
    orthonormalize_against(m_P, at, m_P.middleCols(at, m_lk));
    m_at = at, m_bw = m_lk;
    ++m_blocks;
    if (stop || m_blocks >= m_max_blocks) m_phase = Phase::project, m_K.resize(0, 0);
  }

  // The result once done: U on every process, this process's rows of SxV (zero elsewhere).
  SvdResult result(const ChunkSource& src, const std::vector<size_t>& chunks, MatrixXfR& sxv) {
    MatrixXd E;
    SvdResult r = spectrum_of(m_G, m_w, m_energy, m_opt, "randomized (streamed)", E);
    r.iterations = m_blocks;
    const Index rank = r.S.size();
    const MatrixXd Ek = E.leftCols(rank);
    r.U = (m_P.leftCols(m_w) * Ek).cast<float>();
    m_P.resize(0, 0);
    sxv = MatrixXfR::Zero(Index(src.texels()), rank);
    const MatrixXf Ekf = Ek.cast<float>();
    for (size_t c : chunks) sxv.middleRows(Index(src.chunk_first(c)), m_wt[c].rows()) = m_wt[c].leftCols(m_w) * Ekf;
    m_wt.clear();
    return r;
  }

 private:
  // acc += Y (double += float), in parallel over columns: with the CLI's chunks (~3300 texels at
  // UBO2003 size) a serial m x l add per chunk took a tenth of a pass. Element-wise: the result
  // does not depend on the thread count.
  static void add_into(Eigen::Map<MatrixXd> acc, const MatrixXf& Y) {
#pragma omp parallel for schedule(static)
    for (Index j = 0; j < Y.cols(); ++j) acc.col(j) += Y.col(j).cast<double>();
  }
  // W^T = B^T P of the owned chunks (count x width each), filled block by block: pass b's first
  // product Z = B_c^T Q_b is its block column, so the last pass only adds the newest block's.
  Eigen::Block<MatrixXf, Eigen::Dynamic, Eigen::Dynamic, true> wt_block(size_t c, size_t count) {
    if (m_wt[c].rows() != Index(count)) m_wt[c].resize(Index(count), m_width);
    return m_wt[c].middleCols(m_at, m_bw);
  }

  size_t m_m;
  SvdOptions m_opt;
  // The first block's width l, the later blocks' lk = min(l, C), the basis' capacity (l + (kept
  // - 1) lk), the columns the project pass completes; the current block's first column and width.
  Index m_l, m_lk = 0, m_width = 0, m_w = 0, m_at = 0, m_bw = 0;
  int m_max_blocks = 1, m_kept = 1, m_blocks = 0;
  Phase m_phase = Phase::sketch;
  Sketch m_sketch;  // on the texels
  std::vector<float> m_scratch;  // the sketch's row blocks (dense sketch: column_sketch_product)
  // Sparse sketch: B S summed over the owned chunks (m x s), at m_sums_at with leading dimension
  // m_sums_ld: m_w_sums (slice()) or the caller's stacked sums (use_sketch_sums); null before either.
  std::vector<float> m_w_sums;
  const float* m_sums_at = nullptr;
  size_t m_sums_ld = 0;
  double m_energy = 0, m_last_err = -1;
  MatrixXd m_P, m_K, m_G;  // the basis (m x kept l), its Gram matrix P^T B B^T P, W W^T
  std::optional<StagedY> m_q;  // this pass's Q, staged once for every part's B^T Q
  MatrixXf m_y;
  std::vector<MatrixXf> m_wt;
};

// Texels of a split part: ~8 M values per channel (32 MB) or the chunk, if smaller. Smaller parts
// stay nearer the cache, but every product call stages its m x l operand: at UBO2003 size a
// randomized dfmf encode took 9.0 s with 2 M, 7.1 s with 8 M and 7.5 s with 32 M values.
constexpr size_t k_split_values = size_t(8) << 20;

size_t part_texels(size_t rows, size_t max_count) { return std::max<size_t>(1, std::min(max_count, k_split_values / std::max<size_t>(1, rows))); }

}  // namespace

Result<std::vector<SvdResult>> streaming_svds(const ChunkSource& src, const std::vector<size_t>& chunks, const ChunkSplit* split,
                                              const std::vector<SvdOptions>& opts, Collective& coll, StreamStats* stats_out,
                                              int kept_blocks) {
  const size_t m = split ? split->rows : src.rows(), n = src.texels();
  const size_t channels = split ? size_t(split->channels) : 1;
  if (m == 0 || n == 0) return invalid_argument("SVD of an empty matrix");
  if (opts.size() != channels)
    return invalid_argument("streamed SVD: " + std::to_string(opts.size()) + " option sets for " + std::to_string(channels) + " matrices");
  for (const SvdOptions& o : opts)
    if (o.max_rank < 1) return invalid_argument("SVD rank must be >= 1");
  // The passes run btfc's OpenMP kernels; the small BLAS products between and within them (the
  // orthonormalisation, W^T W per chunk) would leave OpenBLAS's own threads spinning against
  // them for the 2 cores: 2.5-2.8 s instead of 2.2-2.3 s at rank 32, q 1, UBO2003 size. (Where
  // btfc's kernels do not run, the passes' products are OpenBLAS's on OpenMP slices, one BLAS
  // thread each: core/thin_product.h.)
  SingleThreadedBlas serial_blas;
  std::vector<Krylov> ks;
  int total_passes = 0;
  for (const SvdOptions& o : opts) {
    ks.emplace_back(m, n, src.num_chunks(), o, kept_blocks);
    total_passes = std::max(total_passes, ks.back().max_passes());
  }
  PassRunner run(src, chunks, coll, opts[0].progress, split ? "fmf streamed SVDs" : "fmf streamed SVD", total_passes);
  size_t part = 0;  // texels per split part
  // The split parts' scratch (96 MB: 3 x 8 M values), written by the split before any read: on
  // huge pages and not zeroed (a zeroed vector was 0.3 s of the main thread faulting fresh pages
  // on this project's VMs, the other core idle, in a 4.6 s out-of-core dfmf encode at UBO2003 size).
  std::unique_ptr<float, PageFree> parts;
  if (split) {
    size_t max_count = 0;
    for (size_t c : chunks) max_count = std::max(max_count, src.chunk_count(c));
    part = split->part_values ? std::max<size_t>(1, std::min(max_count, split->part_values / m)) : part_texels(m, max_count);
    if (bool(split->in_place) != bool(split->split_in_place) || (split->in_place && channels * m != src.rows()))
      return invalid_argument("streamed SVDs in place: " + std::to_string(channels) + " x " + std::to_string(m) +
                              " rows per part where the source has " + std::to_string(src.rows()) + ", or no split in place");
    if (!split->in_place) parts.reset(static_cast<float*>(page_alloc(channels * m * part * sizeof(float))));
  }
  std::vector<float*> outs(channels);
  // Same sketch in every factorization of a split (color=dfmf's channels at their default
  // ranks): the first pass sums one sketch of each texel's whole column, its channels stacked,
  // instead of one per channel: pieces three times as long, one parallel region instead of three
  // (in place, the three sketches 0.46-0.54 s -> 0.34 s of a UBO2003-size encode; out of core the
  // first pass by a few per cent; docs/benchmarks.md). W has the same bits; the energies are summed
  // by channel in the same call.
  auto same_sketch = [](const Sketch* a, const Sketch* b) {
    return a && b && a->S.m == b->S.m && a->S.s == b->S.s && a->S.layers == b->S.layers && a->S.pick == b->S.pick &&
           a->S.negative == b->S.negative;
  };
  const Sketch* stacked = nullptr;
  if (split) {
    stacked = ks[0].summed_sketch();
    for (const Krylov& k : ks) stacked = same_sketch(stacked, k.summed_sketch()) ? stacked : nullptr;
  }
  std::vector<float> stacked_w;
  std::vector<double> stacked_e;
  if (stacked) stacked_w.assign(channels * m * stacked->S.s, 0.0f), stacked_e.assign(channels, 0.0);
  for (bool first = true;; first = false) {
    std::vector<size_t> active, off;
    size_t payload = 0;
    for (size_t i = 0; i < ks.size(); ++i)
      if (ks[i].phase() != Krylov::Phase::done) {
        ks[i].begin();
        active.push_back(i), off.push_back(payload);
        payload += ks[i].payload();
      }
    if (active.empty()) break;
    auto fn = [&](size_t c, const float* B, size_t k) {
      double* sums = run.sums().data();
      if (!split) {
        for (size_t a = 0; a < active.size(); ++a) ks[active[a]].slice(c, k, src.chunk_first(c), 0, B, k, m, sums + off[a]);
      } else {
        // Split a part, then every unfinished channel's products on it while it is near the cache.
        // In place: split once, in the first pass, each column where it was (ChunkSplit).
        for (size_t o = 0; o < k; o += part) {
          const size_t h = std::min(part, k - o);
          // Each column's matrices one after the other (in place, and in the part buffer for the
          // first pass's stacked sketch), else each matrix contiguous: the later passes' products
          // ran 3-6 % slower on the stacked parts out of core (docs/benchmarks.md).
          const bool stack = split->in_place || (first && stacked);
          const size_t ld = stack ? channels * m : m;
          float* const at = split->in_place ? split->in_place(c, o) : parts.get();
          for (size_t i = 0; i < channels; ++i) outs[i] = at + i * (stack ? m : m * h);
          if (split->in_place) {
            if (first) split->split_in_place(c, o, at, h);
          } else {
            split->split(c, o, B + o * src.rows(), h, outs.data(), ld);
          }
          if (first && stacked) {
            column_sketch_sums(at, ld, h, *stacked, stacked_w.data(), stacked_e.data(), src.chunk_first(c) + o, ld, m);
            continue;
          }
          for (size_t a = 0; a < active.size(); ++a)
            ks[active[a]].slice(c, k, src.chunk_first(c), o, outs[active[a]], h, ld, sums + off[a]);
        }
      }
      for (size_t i : active) ks[i].end_chunk(c);
    };
    auto pack = [&](double* d) {
      if (first && stacked)
        for (size_t i = 0; i < channels; ++i) ks[i].use_sketch_sums(stacked_w.data() + i * m, channels * m, stacked_e[i]);
      for (size_t a = 0; a < active.size(); ++a) ks[active[a]].pack(d + off[a]);
      if (first && stacked) std::vector<float>().swap(stacked_w);
    };
    BTFC_RETURN_IF_ERROR(run.pass(payload, fn, pack));
    // The input check (ooc_svd.h): every process sees the same sums, so all return here alike.
    for (size_t a = 0; a < active.size(); ++a)
      if (!ks[active[a]].finite_energy(run.sums().data() + off[a]))
        return corrupt_data("streamed SVD input: matrix " + std::to_string(active[a]) + " holds a non-finite value (NaN or infinity)" +
                            (split && split->non_finite_cause ? split->non_finite_cause(active[a]) : std::string()));
    // The steps between passes (orthonormalisation, the stopping test) are each factorization's
    // own: color=dfmf's three on both threads (on one, they left the other idle for 3 % of an
    // encode at UBO2003 size; docs/benchmarks.md). The same bits in any order.
#pragma omp parallel for schedule(dynamic, 1) if (active.size() > 1)
    for (long long a = 0; a < (long long)active.size(); ++a) ks[active[size_t(a)]].end(run.sums().data() + off[size_t(a)]);
    if (first) BTFC_RETURN_IF_ERROR(src.finish_first_pass(coll));
  }
  run.release();
  parts.reset();
  // The results too (the Ritz step, SxV), then the gathers in order (collectives).
  std::vector<SvdResult> rs(ks.size());
  std::vector<MatrixXfR> sxvs(ks.size());
#pragma omp parallel for schedule(dynamic, 1) if (ks.size() > 1)
  for (long long i = 0; i < (long long)ks.size(); ++i) rs[size_t(i)] = ks[size_t(i)].result(src, chunks, sxvs[size_t(i)]);
  for (size_t i = 0; i < ks.size(); ++i) {
    BTFC_RETURN_IF_ERROR(run.gather(rs[i], sxvs[i]));
    MatrixXfR().swap(sxvs[i]);
  }
  run.done(stats_out);
  return rs;
}

Result<SvdResult> streaming_svd(const ChunkSource& src, const std::vector<size_t>& chunks, const SvdOptions& opt, Collective& coll,
                                StreamStats* stats_out, int kept_blocks) {
  BTFC_ASSIGN_OR_RETURN(std::vector<SvdResult> rs, streaming_svds(src, chunks, nullptr, {opt}, coll, stats_out, kept_blocks));
  return std::move(rs[0]);
}

}  // namespace btfc::fmf
