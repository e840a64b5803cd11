// dfmf channel chunk sources; see ooc_dfmf.h.
#include "codecs/fmf/ooc_dfmf.h"

#include "codecs/fmf/fmf.h"

namespace btfc {

DfmfChannelSource::DfmfChannelSource(const fmf::ChunkSource& base, int k)
    : m_base(base), m_k(k), m_clamped(new std::atomic<uint64_t>[base.num_chunks()]) {
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
  for (size_t t = 0; t < count; ++t) clamped += dfmf_channel(b + t * in_rows, rows, m_k, dst + t * rows);
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

uint64_t DfmfChannelSource::clamped() const {
  uint64_t total = 0;
  for (size_t c = 0; c < num_chunks(); ++c) total += m_clamped[c];
  return total;
}

}  // namespace btfc
