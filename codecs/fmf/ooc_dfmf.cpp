// dfmf channel chunk sources; see ooc_dfmf.h.
#include "codecs/fmf/ooc_dfmf.h"

#include <algorithm>
#include <cstring>
#include <omp.h>
#include <vector>

#include "codecs/fmf/fmf.h"

namespace btfc {

DfmfChannelSource::DfmfChannelSource(const ChunkSource& base, int k, float offset)
    : m_base(base), m_k(k), m_offset(offset), m_clamped(new std::atomic<uint64_t>[base.num_chunks()]) {
  for (size_t c = 0; c < base.num_chunks(); ++c) m_clamped[c] = 0;
}

// The float scratch rounded up to 64 bytes, so the base's raw bytes behind it stay aligned.
size_t DfmfChannelSource::scratch_bytes(size_t values) { return (values * sizeof(float) + 63) / 64 * 64; }

size_t DfmfChannelSource::raw_buffer_bytes(size_t c) const {
  if (m_base.mappable()) return 0;
  return scratch_bytes(m_base.rows() * m_base.chunk_count(c)) + m_base.raw_buffer_bytes(c);
}

Status DfmfChannelSource::transform(size_t c, const float* b, float* dst) const {
  const size_t rows = this->rows(), in_rows = m_base.rows(), count = chunk_count(c);
  if (in_rows != 3 * rows) return invalid_argument("color=dfmf needs 3 channels: the BTF matrix has " + std::to_string(in_rows) + " rows");
  uint64_t clamped = 0;
  for (size_t t = 0; t < count; ++t) clamped += dfmf_channel(b + t * in_rows, rows, m_k, m_offset, dst + t * rows);
  if (m_k == 0) m_clamped[c] = clamped;
  return {};
}

Status DfmfChannelSource::decode(size_t c, const void* raw, float* dst) const {
  std::vector<float> base(m_base.rows() * chunk_count(c));
  BTFC_RETURN_IF_ERROR(m_base.decode(c, raw, base.data()));
  return transform(c, base.data(), dst);
}

Status DfmfChannelSource::load(size_t c, void* raw, float* dst) const {
  if (m_base.mappable()) {
    BTFC_ASSIGN_OR_RETURN(const float* b, m_base.map(c));
    Status s = transform(c, b, dst);
    m_base.unmap(c, b);
    return s;
  }
  // raw = [float scratch for the base chunk | the base's raw buffer].
  float* scratch = static_cast<float*>(raw);
  uint8_t* base_raw = static_cast<uint8_t*>(raw) + scratch_bytes(m_base.rows() * chunk_count(c));
  BTFC_RETURN_IF_ERROR(m_base.load(c, m_base.raw_buffer_bytes(c) ? base_raw : nullptr, scratch));
  return transform(c, scratch, dst);
}

Result<double> DfmfChannelSource::auto_offset(const ChunkSource& base, const std::vector<size_t>& chunks, Collective& coll) {
  const size_t in_rows = base.rows();
  const std::vector<size_t> sample = dfmf_offset_sample(base.texels());
  // Per sample texel its two sums. Each process fills the slots of the texels in its chunks; the
  // others' stay 0, so the sum over the processes is exact and every process adds the same table
  // in the same order.
  std::vector<double> sums(2 * sample.size(), 0.0);
  Status local;
  if (in_rows % 3 != 0) local = invalid_argument("color=dfmf needs 3 channels: the BTF matrix has " + std::to_string(in_rows) + " rows");
  std::vector<float> values;
  std::vector<uint8_t> raw;
  // The first sight of every chunk: the source's checks (a raw .btfc's CRC and finite test) on
  // all threads, nothing else runs meanwhile (2.5-3.1 -> 1.6-1.8 s on the UBO2003-size BTF in one
  // run on a slow stretch of the host; docs/benchmarks.md). Leaving them to the first pass and
  // reading only the sample was no faster with the file cached and slower from disk (the pass's
  // reader thread checks alone; docs/benchmarks.md, fifteenth session of 2026-12-06).
  const CheckThreads wide(omp_get_max_threads());
  for (size_t ci = 0; ci < chunks.size() && local.ok(); ++ci) {
    const size_t c = chunks[ci], first = base.chunk_first(c);
    const float* b = nullptr;
    if (base.mappable()) {
      auto m = base.map(c);
      if (!m.ok()) {
        local = m.status();
        break;
      }
      b = m.value();
    } else {
      values.resize(in_rows * base.chunk_count(c));
      raw.resize(base.raw_buffer_bytes(c));
      local = base.load(c, raw.empty() ? nullptr : raw.data(), values.data());
      if (!local.ok()) break;
      b = values.data();
    }
    // The sample texels in this chunk: [lo, hi).
    const size_t lo = size_t(std::lower_bound(sample.begin(), sample.end(), first) - sample.begin()),
                 hi = size_t(std::lower_bound(sample.begin(), sample.end(), first + base.chunk_count(c)) - sample.begin());
#pragma omp parallel for schedule(static)
    for (long long i = (long long)lo; i < (long long)hi; ++i)
      dfmf_luminance_moments(b + (sample[size_t(i)] - first) * in_rows, in_rows / 3, &sums[2 * size_t(i)], &sums[2 * size_t(i) + 1]);
    if (base.mappable()) base.unmap(c, b);
  }
  // Every process joins the sum, then all agree on the first failure (no process waits alone).
  BTFC_RETURN_IF_ERROR(coll.allreduce_sum(sums.data(), sums.size()));
  BTFC_RETURN_IF_ERROR(coll.agree(local));
  return dfmf_offset_from_sample(sums);
}

uint64_t DfmfChannelSource::clamped() const {
  uint64_t total = 0;
  for (size_t c = 0; c < num_chunks(); ++c) total += m_clamped[c];
  return total;
}

Result<std::vector<SvdResult>> dfmf_streaming_svds(const ChunkSource& base, const std::vector<size_t>& chunks, float offset,
                                                   const SvdOptions& opt_y, const SvdOptions& opt_c, Collective& coll,
                                                   StreamStats* stats, int kept_blocks, double* clamped, float* in_place) {
  const size_t in_rows = base.rows(), rows = in_rows / 3;
  if (in_rows % 3 != 0 || rows == 0)
    return invalid_argument("color=dfmf needs 3 channels: the BTF matrix has " + std::to_string(in_rows) + " rows");
  // Per chunk, set (not added) on the chunk's first part of every pass: each chunk counts once.
  std::vector<uint64_t> per_chunk(base.num_chunks(), 0);
  auto count = [&](size_t c, size_t o, uint64_t n) { per_chunk[c] = (o == 0 ? 0 : per_chunk[c]) + n; };
  fmf::ChunkSplit split;
  split.channels = 3, split.rows = rows;
  // Finite RGB values give a non-finite channel only where Y + e (or a chroma sum) passes the
  // largest float: data near 3.4e38.
  split.non_finite_cause = [](size_t i) {
    return std::string(i == 0 ? " in Y'" : i == 1 ? " in U'" : " in V'") +
           ": from a NaN or infinity in the BTF, or finite values whose luminance + offset pass the float range (3.4e38); "
           "scale the BTF down";
  };
  split.split = [&](size_t c, size_t o, const float* B, size_t k, float* const* out, size_t ld) {
    uint64_t n = 0;
#pragma omp parallel for reduction(+ : n) schedule(static)
    for (long long t = 0; t < (long long)k; ++t) {
      const size_t at = size_t(t) * ld;
      n += dfmf_channels(B + size_t(t) * in_rows, rows, offset, out[0] + at, out[1] + at, out[2] + at);
    }
    count(c, o, n);
  };
  if (in_place) {
    // Each texel's RGB column becomes its Y', U', V' columns, one after the other, through a
    // per-thread column (in L2) copied back over it.
    split.in_place = [&](size_t c, size_t o) { return in_place + (base.chunk_first(c) + o) * in_rows; };
    split.split_in_place = [&](size_t c, size_t o, float* B, size_t k) {
      uint64_t n = 0;
#pragma omp parallel reduction(+ : n)
      {
        std::vector<float> col(in_rows);
#pragma omp for schedule(static)
        for (long long t = 0; t < (long long)k; ++t) {
          float* const b = B + size_t(t) * in_rows;
          n += dfmf_channels(b, rows, offset, col.data(), col.data() + rows, col.data() + 2 * rows);
          std::memcpy(b, col.data(), in_rows * sizeof(float));
        }
      }
      count(c, o, n);
    };
  }
  auto rs = fmf::streaming_svds(base, chunks, &split, {opt_y, opt_c, opt_c}, coll, stats, kept_blocks);
  for (size_t c : chunks) *clamped += double(per_chunk[c]);
  return rs;
}

}  // namespace btfc
