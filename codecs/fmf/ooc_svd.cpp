// Streaming randomized SVD; see ooc_svd.h for the algorithm and the contracts.
#include "codecs/fmf/ooc_svd.h"

#include <Eigen/Dense>
#include <chrono>
#include <cmath>
#include <algorithm>
#include <functional>
#include <future>
#include <random>

namespace btfc::fmf {
namespace {

using Eigen::Index;
using Eigen::MatrixXd;
using Eigen::MatrixXf;
using Clock = std::chrono::steady_clock;

double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

// Orthonormal basis of Y's columns (thin Householder QR in double, as the in-core path).
MatrixXf orthonormalize(const MatrixXd& Y) {
  Eigen::HouseholderQR<MatrixXd> qr(Y);
  MatrixXd Q = qr.householderQ() * MatrixXd::Identity(Y.rows(), Y.cols());
  return Q.cast<float>();
}

// Omega's rows for texels [first, first + count): Gaussian, Box-Muller on raw 64-bit draws (as
// svd.cpp) from an engine seeded by (seed, first), so any process can make any chunk's rows.
void gaussian_rows(uint64_t seed, size_t first, size_t count, Index l, MatrixXf& out) {
  std::seed_seq seq{uint32_t(seed), uint32_t(seed >> 32), uint32_t(first), uint32_t(uint64_t(first) >> 32)};
  std::mt19937_64 rng(seq);
  out.resize(Index(count), l);
  const double k_two_pi = 6.283185307179586;
  for (Index i = 0; i < out.size(); i += 2) {
    const double u1 = (double(rng() >> 11) + 0.5) * (1.0 / 9007199254740992.0);
    const double u2 = (double(rng() >> 11) + 0.5) * (1.0 / 9007199254740992.0);
    const double rad = std::sqrt(-2.0 * std::log(u1));
    out.data()[i] = float(rad * std::cos(k_two_pi * u2));
    if (i + 1 < out.size()) out.data()[i + 1] = float(rad * std::sin(k_two_pi * u2));
  }
}

struct Buffers {
  std::vector<uint8_t> raw;
  std::vector<float> block[2];
};

// Reads and decodes (or maps) the owned chunks in order on a helper thread, one chunk ahead of
// `fn`, which multiplies the previous one. The helper does all the I/O and the conversion, so the
// main thread only runs GEMMs (no OpenMP region between them whose spinning threads would
// compete with the BLAS threads). Stops at the first failure (after the helper finished).
Status for_each_chunk(const ChunkSource& src, const std::vector<size_t>& chunks, Buffers& b, StreamStats& st,
                      const std::function<void(size_t c, const float* B, size_t count)>& fn) {
  if (chunks.empty()) return {};
  const bool mapped = src.mappable();
  auto load = [&](size_t i) {
    return std::async(std::launch::async, [&src, &b, &chunks, i, mapped]() -> Result<const float*> {
      if (mapped) return src.map(chunks[i]);
      float* dst = b.block[i % 2].data();
      Status s = src.load(chunks[i], b.raw.empty() ? nullptr : b.raw.data(), dst);
      if (!s.ok()) return s;
      return static_cast<const float*>(dst);
    });
  };
  std::future<Result<const float*>> next = load(0);
  for (size_t i = 0; i < chunks.size(); ++i) {
    Result<const float*> cur = next.get();
    if (i + 1 < chunks.size() && cur.ok()) next = load(i + 1);
    if (!cur.ok()) {
      if (next.valid()) {
        Result<const float*> other = next.get();
        if (mapped && other.ok()) src.unmap(chunks[i + 1], *other);
      }
      return cur.status();
    }
    st.bytes_read += src.raw_bytes(chunks[i]);
    fn(chunks[i], *cur, src.chunk_count(chunks[i]));
    if (mapped) src.unmap(chunks[i], *cur);
  }
  return {};
}

}  // namespace

std::vector<size_t> owned_chunks(const ChunkSource& src, int rank, int size) {
  const size_t n = src.num_chunks();
  std::vector<size_t> out;
  for (size_t c = n * size_t(rank) / size_t(size); c < n * size_t(rank + 1) / size_t(size); ++c) out.push_back(c);
  return out;
}

Result<SvdResult> streaming_svd(const ChunkSource& src, const std::vector<size_t>& chunks, const SvdOptions& opt, Collective& coll,
                                StreamStats* stats_out) {
  const size_t m = src.rows(), n = src.texels();
  if (m == 0 || n == 0) return invalid_argument("SVD of an empty matrix");
  if (opt.max_rank < 1) return invalid_argument("SVD rank must be >= 1");
  const Index l = Index(std::min<size_t>(std::min(m, n), size_t(opt.max_rank) + size_t(opt.oversample)));
  StreamStats st;
  Buffers b;
  size_t max_raw = 0, max_count = 0;
  for (size_t c : chunks) max_raw = std::max(max_raw, src.raw_buffer_bytes(c)), max_count = std::max(max_count, src.chunk_count(c));
  Status local;
  if (src.mappable()) {
    st.buffer_bytes = 2 * 4 * max_count * m;  // two mapped float chunks
  } else {
    try {
      b.raw.resize(max_raw);
      b.block[0].resize(max_count * m);
      b.block[1].resize(max_count * m);
    } catch (const std::bad_alloc&) {
      local = io_error("out of memory allocating the chunk buffers (" + std::to_string(max_raw + 8 * max_count * m) + " bytes)");
    }
    st.buffer_bytes = max_raw + 8 * max_count * m;
  }
  const int total_passes = opt.power_iters + 2;
  if (opt.progress) opt.progress->start("fmf out-of-core SVD", uint64_t(total_passes) * chunks.size());

  // One pass = the chunks, then one collective sum of `buf` whose last element is the error flag.
  std::vector<double> buf;
  // `pack` copies the local sums into buf[0, payload) before the collective sum.
  auto pass = [&](size_t payload, const std::function<void(size_t, const float*, size_t)>& fn,
                  const std::function<void(double*)>& pack) -> Status {
    const auto t0 = Clock::now();
    buf.assign(payload + 1, 0.0);
    if (local.ok())
      local = for_each_chunk(src, chunks, b, st, [&](size_t c, const float* B, size_t k) {
        fn(c, B, k);
        if (opt.progress) opt.progress->advance();
      });
    if (local.ok()) pack(buf.data());
    buf[payload] = local.ok() ? 0.0 : 1.0;
    const auto r0 = Clock::now();
    Status s = coll.allreduce_sum(buf.data(), buf.size());
    st.reduce_seconds += since(r0);
    st.reduce_bytes += buf.size() * sizeof(double);
    ++st.passes;
    st.pass_seconds.push_back(since(t0));
    if (!s.ok()) return s;
    if (buf[payload] > 0) return coll.agree(local);  // every process takes this branch together
    return {};
  };

  // Pass 0: sketch and energy.
  MatrixXd Y = MatrixXd::Zero(Index(m), l);
  double energy = 0;
  {
    MatrixXf Om, Yf;
    auto sketch = [&](size_t c, const float* Bp, size_t k) {
      Eigen::Map<const MatrixXf> B(Bp, Index(m), Index(k));
      // Column sums in float (short), accumulated in double; serial: see for_each_chunk.
      for (Index j = 0; j < Index(k); ++j) energy += double(B.col(j).squaredNorm());
      gaussian_rows(opt.seed, src.chunk_first(c), k, l, Om);
      Yf.noalias() = B * Om;
      Y += Yf.cast<double>();
    };
    BTFC_RETURN_IF_ERROR(pass(m * size_t(l) + 1, sketch, [&](double* d) {
      std::copy(Y.data(), Y.data() + Y.size(), d);
      d[Y.size()] = energy;
    }));
    Y = Eigen::Map<MatrixXd>(buf.data(), Index(m), l);
    energy = buf[m * size_t(l)];
  }
  BTFC_RETURN_IF_ERROR(src.finish_first_pass(coll));
  // Passes 1..q: Y = B B^T Q.
  MatrixXf Q = orthonormalize(Y);
  for (int it = 0; it < opt.power_iters; ++it) {
    Y.setZero();
    MatrixXf Z, Yf;
    auto power = [&](size_t, const float* Bp, size_t k) {
      Eigen::Map<const MatrixXf> B(Bp, Index(m), Index(k));
      Z.noalias() = B.transpose() * Q;
      Yf.noalias() = B * Z;
      Y += Yf.cast<double>();
    };
    BTFC_RETURN_IF_ERROR(pass(m * size_t(l), power, [&](double* d) { std::copy(Y.data(), Y.data() + Y.size(), d); }));
    Y = Eigen::Map<MatrixXd>(buf.data(), Index(m), l);
    Q = orthonormalize(Y);
  }
  Y.resize(0, 0);
  // Last pass: W^T = B^T Q for the owned texels, and its Gram matrix.
  std::vector<std::pair<size_t, MatrixXf>> wt;  // (chunk, rows of W^T)
  MatrixXd G = MatrixXd::Zero(l, l);
  auto project = [&](size_t c, const float* Bp, size_t k) {
    Eigen::Map<const MatrixXf> B(Bp, Index(m), Index(k));
    MatrixXf W = B.transpose() * Q;
    G += (W.transpose() * W).cast<double>();
    wt.emplace_back(c, std::move(W));
  };
  BTFC_RETURN_IF_ERROR(pass(size_t(l * l), project, [&](double* d) { std::copy(G.data(), G.data() + G.size(), d); }));
  G = Eigen::Map<MatrixXd>(buf.data(), l, l);
  b = Buffers{};

  Eigen::VectorXd lambda;
  MatrixXd E;
  top_eigenpairs(G, l, lambda, E);
  SvdResult r;
  r.method = "randomized (streamed)";
  r.requested_rank = opt.max_rank;
  r.total_energy = energy;
  const int rank = choose_rank(lambda, energy, opt, r.data_rank_limit, r.target_reached);
  r.S = lambda.head(rank).cwiseSqrt();
  r.kept_energy = lambda.head(rank).sum();
  const MatrixXd Ek = E.leftCols(rank);
  r.U = (Q.cast<double>() * Ek).cast<float>();
  // SxV rows of the owned texels, summed (disjoint rows: exact) into process 0.
  MatrixXfR sxv = MatrixXfR::Zero(Index(n), rank);
  const MatrixXf Ekf = Ek.cast<float>();
  for (auto& [c, W] : wt) sxv.middleRows(Index(src.chunk_first(c)), W.rows()) = W * Ekf;
  wt.clear();
  const auto r0 = Clock::now();
  Status s = coll.reduce_sum_to_root(sxv.data(), size_t(sxv.size()));
  st.reduce_seconds += since(r0);
  st.reduce_bytes += uint64_t(sxv.size()) * 4;
  BTFC_RETURN_IF_ERROR(s);
  if (coll.rank() == 0) r.SxV = std::move(sxv);
  if (opt.progress) opt.progress->finish();
  if (stats_out) *stats_out = std::move(st);
  return r;
}

}  // namespace btfc::fmf
