// Streaming (out-of-core, distributed) SVDs of a BTF matrix B (m rows x n texel columns) that is
// read in column chunks, never held whole. Two algorithms, both ending every pass with one
// collective sum (the pass machinery and its failure handling are shared: ooc_pass.h).
//
// Randomized (streaming_svd): Halko, Martinsson, Tropp 2011, Alg. 4.4 (randomized range finder
// with power iterations), arranged so that every pass reads B exactly once:
//   pass 0        Y = B Omega, ||B||_F^2                      (Omega: n x l Gaussian, l = C + p)
//   pass 1..q     Y = B (B^T Q)  with Q = orth(Y) before each pass  (per chunk: Z_c = B_c^T Q,
//                 Y += B_c Z_c while the chunk is in memory)
//   pass q+1      W^T = B^T Q and G = W W^T (l x l)
//   then          G = E Lambda E^T, U = Q E_k, SxV = W^T E_k   (k by choose_rank)
// The in-core path (svd.h) applies B and B^T the same number of times (1 + 2q + 1) but reads B
// 2q + 2 times; here it is q + 2 reads, each doing two GEMMs per chunk. The only difference is
// that Z = B^T Q is not re-orthonormalised between the two products (Y is, in double, after
// every pass); with float data and the ranks fmf uses this changes the error by far less than
// 1 % (tests/ooc_test.cpp checks it against the in-core path).
//
// Exact (streaming_exact_svd, ooc_exact.cpp): the in-core exact path's rows-side Gram method in
// two passes: pass 1 G = sum_c B_c B_c^T (m x m, double) and ||B||_F^2, then G = E Lambda E^T
// with the in-core solver and rank choice, U = E_k; pass 2 SxV = B_c^T U per chunk. Needs
// streaming_exact_bytes(m) besides the chunk buffers: for matrices with a small row count
// (few directions, any number of texels). The in-core path's other side (B^T B when texels < m)
// is not streamed: it would need every pair of chunks at once.
//
// Omega's rows for chunk c come from an RNG seeded by (seed, first texel of c), so the result
// does not depend on how chunks are spread over processes. Every pass ends with one collective
// sum over processes (Collective::allreduce_sum) of the m x l (or l x l, or G's lower triangle)
// matrix plus one error flag: a process that fails to read or decode a chunk still joins the
// sum, the flag makes every process stop, and Collective::agree hands all of them the failing
// process's message. Sums run in double, so the result equals the single-process one up to
// float rounding.
//
// Memory: one raw chunk buffer and two float chunks (a helper thread reads and decodes the next
// chunk while the current one is multiplied), or two mapped chunks for a mappable source, plus
// O((m + n_local) l) for Y, Q and W^T (randomized) or streaming_exact_bytes(m) (exact). The
// caller sizes chunks so this stays under its limit (ooc_fmf.h).
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "codecs/fmf/svd.h"
#include "core/status.h"

namespace btfc::fmf {

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
};

// Per-process measurements of one streaming SVD.
struct StreamStats {
  int passes = 0;
  uint64_t bytes_read = 0;            // raw chunk bytes this process read
  std::vector<double> pass_seconds;   // wall time of each pass (including its collective sum)
  double reduce_seconds = 0;          // time inside allreduce_sum / reduce_sum_to_root
  uint64_t reduce_bytes = 0;          // payload of the collective sums (per process)
  uint64_t buffer_bytes = 0;          // chunk buffers allocated
};

// Factorizes B from `chunks` (the chunk indices this process owns; together the processes own
// every chunk exactly once). Returns U (m x C) on every process and SxV (n x C, all texels) on
// process 0 (elsewhere SxV is empty). opt.method is ignored (always randomized); l is clamped
// to min(m, n).
Result<SvdResult> streaming_svd(const ChunkSource& src, const std::vector<size_t>& chunks, const SvdOptions& opt, Collective& coll,
                                StreamStats* stats = nullptr);

// The same contract, exactly (the top singular triplets up to double round-off, as truncated_svd
// with SvdMethod::exact when m <= n) in 2 passes; opt.method, oversample, power_iters and seed
// are ignored. Holds streaming_exact_bytes(m) besides the chunk buffers; the caller checks that
// this fits (it is not checked here).
Result<SvdResult> streaming_exact_svd(const ChunkSource& src, const std::vector<size_t>& chunks, const SvdOptions& opt, Collective& coll,
                                      StreamStats* stats = nullptr);
// Bytes streaming_exact_svd holds for m rows besides the chunk buffers and SxV: the Gram matrix,
// the eigen-solver's workspace and one double column block.
uint64_t streaming_exact_bytes(uint64_t m);

// The chunks process `rank` of `size` owns: a contiguous range, balanced by texel count.
std::vector<size_t> owned_chunks(const ChunkSource& src, int rank, int size);

}  // namespace btfc::fmf
