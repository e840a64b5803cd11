// Column chunks of a BTF matrix and the collective sums over the processes that share one
// factorization: the data-only interface between whoever reads a BTF in pieces (formats/: raw
// .btfc in place, Bonn BDI working files) and whoever streams over it (codecs' out-of-core
// encoders, btfc-mpi's MPI collective). Rows are a texel's values (directions x channels), a
// chunk is a contiguous run of texels (columns).
#pragma once
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

#include "core/status.h"

namespace btfc {

class Collective;

// Column chunks of B. read() does the I/O (called from a helper thread, may run concurrently
// with decode() of another chunk); decode() turns raw bytes into a column-major float block
// (rows() x chunk_count(c)).
class ChunkSource {
 public:
  virtual ~ChunkSource() = default;
  virtual size_t rows() const = 0;
  virtual size_t num_chunks() const = 0;
  virtual size_t chunk_first(size_t c) const = 0;  // first texel (column)
  virtual size_t chunk_count(size_t c) const = 0;  // texels in chunk c
  virtual size_t raw_bytes(size_t c) const = 0;    // bytes read() fetches
  virtual Status read(size_t c, void* raw) const = 0;
  virtual Status decode(size_t c, const void* raw, float* dst) const = 0;
  // read() then decode() into dst; a source may do both at once without the raw buffer (then
  // raw_buffer_bytes() is 0 and `raw` is null).
  virtual Status load(size_t c, void* raw, float* dst) const {
    Status s = read(c, raw);
    return s.ok() ? decode(c, raw, dst) : s;
  }
  virtual size_t raw_buffer_bytes(size_t c) const { return raw_bytes(c); }
  // Zero-copy alternative to read() + decode(): a source whose file holds chunk c as a float
  // column block already may map it instead. When mappable(), streaming_svd allocates no chunk
  // buffers; it calls map() on the helper thread (at most two chunks mapped at once) and
  // unmap() once the chunk is multiplied. Both thread-safe.
  virtual bool mappable() const { return false; }
  virtual Result<const float*> map(size_t c) const { return unsupported("this chunk source cannot map chunks"); }
  virtual void unmap(size_t c, const float* p) const {}
  // Called by every process once the first pass has seen every chunk (each by its owner): a
  // source whose integrity check spans the whole file (a raw .btfc's tensor CRC) combines the
  // processes' parts here through `coll`, and every process returns the same status.
  virtual Status finish_first_pass(Collective& coll) const { return {}; }
  size_t texels() const { return num_chunks() ? chunk_first(num_chunks() - 1) + chunk_count(num_chunks() - 1) : 0; }
};

// Collective operations over the processes that share a factorization. The default is one
// process: sums are the identity. The MPI one is mpi/mpi_collective.h (btfc-mpi).
class Collective {
 public:
  virtual ~Collective() = default;
  virtual int rank() const { return 0; }
  virtual int size() const { return 1; }
  // In-place element-wise sum over processes, result on every process.
  virtual Status allreduce_sum(double* data, size_t n) { return {}; }
  // In-place sum into process 0 (the others' buffers are left unspecified).
  virtual Status reduce_sum_to_root(float* data, size_t n) { return {}; }
  // Called by every process with its local status: returns the failure of the lowest failing
  // process (the same on all processes), or ok when none failed.
  virtual Status agree(const Status& local) { return local; }
  // Process 0's `s` on every process (one process: unchanged).
  virtual Status broadcast(std::string& s) { return {}; }
};

// A column-major rows x texels float matrix already in memory (an in-memory Btf's data) as chunks
// of `per` texels, mapped without a copy: in-memory data through the streamed passes (fmf's
// color=dfmf encode, codecs/fmf/ooc_svd.h). The matrix must outlive the source.
class MatrixChunks final : public ChunkSource {
 public:
  MatrixChunks(const float* data, size_t rows, size_t texels, size_t per)
      : m_data(data), m_rows(rows), m_texels(texels), m_per(per ? per : 1) {}
  size_t rows() const override { return m_rows; }
  size_t num_chunks() const override { return (m_texels + m_per - 1) / m_per; }
  size_t chunk_first(size_t c) const override { return c * m_per; }
  size_t chunk_count(size_t c) const override { return std::min(m_per, m_texels - c * m_per); }
  size_t raw_bytes(size_t c) const override { return chunk_count(c) * m_rows * sizeof(float); }
  Status read(size_t c, void* raw) const override {
    std::memcpy(raw, m_data + chunk_first(c) * m_rows, raw_bytes(c));
    return {};
  }
  Status decode(size_t c, const void* raw, float* dst) const override {
    std::memcpy(dst, raw, raw_bytes(c));
    return {};
  }
  bool mappable() const override { return true; }
  Result<const float*> map(size_t c) const override { return m_data + chunk_first(c) * m_rows; }

 private:
  const float* m_data;
  size_t m_rows, m_texels, m_per;
};

// How many threads a source's first-sight checks of a chunk (a raw .btfc's CRC and finite test
// in map() or load()) may use on the calling thread: 1 unless a scope on this thread raised it.
// The streamed passes map on a helper thread while the GEMMs hold every core, where a second
// team only competes with them; a sweep that only reads (color=dfmf's automatic offset, the first
// sight of every chunk there) raises it for its own thread, whose cores are otherwise idle.
class CheckThreads {
 public:
  explicit CheckThreads(int n) : m_prev(t_n) { t_n = std::max(1, n); }
  ~CheckThreads() { t_n = m_prev; }
  CheckThreads(const CheckThreads&) = delete;
  CheckThreads& operator=(const CheckThreads&) = delete;
  static int get() { return t_n; }

 private:
  int m_prev;
  static inline thread_local int t_n = 1;
};

// The chunks process `rank` of `size` owns: a contiguous range, balanced by chunk count.
inline std::vector<size_t> owned_chunks(const ChunkSource& src, int rank, int size) {
  const size_t n = src.num_chunks();
  std::vector<size_t> out;
  for (size_t c = n * size_t(rank) / size_t(size); c < n * size_t(rank + 1) / size_t(size); ++c) out.push_back(c);
  return out;
}

}  // namespace btfc
