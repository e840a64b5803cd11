// Pass machinery of the streamed SVDs; see ooc_pass.h.
#include "codecs/fmf/ooc_pass.h"

#include <future>

namespace btfc::fmf {
namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

}  // namespace

PassRunner::PassRunner(const ChunkSource& src, const std::vector<size_t>& chunks, Collective& coll, Progress* progress,
                       const std::string& label, int passes)
    : m_src(src), m_chunks(chunks), m_coll(coll), m_progress(progress) {
  const size_t m = src.rows();
  size_t max_raw = 0, max_count = 0;
  for (size_t c : chunks) max_raw = std::max(max_raw, src.raw_buffer_bytes(c)), max_count = std::max(max_count, src.chunk_count(c));
  if (src.mappable()) {
    m_st.buffer_bytes = 2 * 4 * max_count * m;  // two mapped float chunks
  } else {
    try {
      m_b.raw.resize(max_raw);
      m_b.block[0].resize(max_count * m);
      m_b.block[1].resize(max_count * m);
    } catch (const std::bad_alloc&) {
      m_local = io_error("out of memory allocating the chunk buffers (" + std::to_string(max_raw + 8 * max_count * m) + " bytes)");
    }
    m_st.buffer_bytes = max_raw + 8 * max_count * m;
  }
  if (m_progress) m_progress->start(label, uint64_t(passes) * chunks.size());
}

// Reads and decodes (or maps) the owned chunks in order on a helper thread, one chunk ahead of
// `fn`, which multiplies the previous one. The helper does all the I/O and the conversion, so the
// main thread only runs GEMMs (no OpenMP region between them whose spinning threads would
// compete with the BLAS threads). Stops at the first failure (after the helper finished).
Status PassRunner::for_each_chunk(const std::function<void(size_t, const float*, size_t)>& fn) {
  if (m_chunks.empty()) return {};
  const bool mapped = m_src.mappable();
  auto load = [&](size_t i) {
    return std::async(std::launch::async, [this, i, mapped]() -> Result<const float*> {
      if (mapped) return m_src.map(m_chunks[i]);
      float* dst = m_b.block[i % 2].data();
      Status s = m_src.load(m_chunks[i], m_b.raw.empty() ? nullptr : m_b.raw.data(), dst);
      if (!s.ok()) return s;
      return static_cast<const float*>(dst);
    });
  };
  std::future<Result<const float*>> next = load(0);
  for (size_t i = 0; i < m_chunks.size(); ++i) {
    Result<const float*> cur = next.get();
    if (i + 1 < m_chunks.size() && cur.ok()) next = load(i + 1);
    if (!cur.ok()) {
      if (next.valid()) {
        Result<const float*> other = next.get();
        if (mapped && other.ok()) m_src.unmap(m_chunks[i + 1], *other);
      }
      return cur.status();
    }
    m_st.bytes_read += m_src.raw_bytes(m_chunks[i]);
    fn(m_chunks[i], *cur, m_src.chunk_count(m_chunks[i]));
    if (mapped) m_src.unmap(m_chunks[i], *cur);
  }
  return {};
}

Status PassRunner::pass(size_t payload, const std::function<void(size_t, const float*, size_t)>& fn,
                        const std::function<void(double*)>& pack) {
  const auto t0 = Clock::now();
  m_buf.assign(payload + 1, 0.0);
  if (m_local.ok())
    m_local = for_each_chunk([&](size_t c, const float* B, size_t k) {
      fn(c, B, k);
      if (m_progress) m_progress->advance();
    });
  if (m_local.ok()) pack(m_buf.data());
  m_buf[payload] = m_local.ok() ? 0.0 : 1.0;
  const auto r0 = Clock::now();
  Status s = m_coll.allreduce_sum(m_buf.data(), m_buf.size());
  m_st.reduce_seconds += since(r0);
  m_st.reduce_bytes += m_buf.size() * sizeof(double);
  ++m_st.passes;
  m_st.pass_seconds.push_back(since(t0));
  if (!s.ok()) return s;
  if (m_buf[payload] > 0) return m_coll.agree(m_local);  // every process takes this branch together
  return {};
}

Status PassRunner::finish(SvdResult& r, MatrixXfR& sxv, StreamStats* stats_out) {
  BTFC_RETURN_IF_ERROR(gather(r, sxv));
  done(stats_out);
  return {};
}

Status PassRunner::gather(SvdResult& r, MatrixXfR& sxv) {
  const auto r0 = Clock::now();
  Status s = m_coll.reduce_sum_to_root(sxv.data(), size_t(sxv.size()));
  m_st.reduce_seconds += since(r0);
  m_st.reduce_bytes += uint64_t(sxv.size()) * 4;
  BTFC_RETURN_IF_ERROR(s);
  if (m_coll.rank() == 0) r.SxV = std::move(sxv);
  return {};
}

void PassRunner::done(StreamStats* stats_out) {
  if (m_progress) m_progress->finish();
  if (stats_out) *stats_out = std::move(m_st);
}

void PassRunner::release() {
  m_b = Buffers{};
  std::vector<double>().swap(m_buf);
}

SvdResult spectrum_of(const Eigen::MatrixXd& G, Eigen::Index l, double energy, const SvdOptions& opt, const char* method, Eigen::MatrixXd& E,
                      Eigen::Index lapack_from) {
  Eigen::VectorXd lambda;
  top_eigenpairs(G, l, lambda, E, lapack_from);
  SvdResult r;
  r.method = method;
  r.requested_rank = opt.max_rank;
  r.total_energy = energy;
  const int rank = choose_rank(lambda, energy, opt, r.data_rank_limit, r.target_reached);
  r.S = lambda.head(rank).cwiseSqrt();
  r.kept_energy = lambda.head(rank).sum();
  return r;
}

}  // namespace btfc::fmf
