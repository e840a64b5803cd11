// The fmf codec out of core: factorizes a BTF stored as an uncompressed Bonn BDI working file
// (formats/bonn/bdi_work.h) chunk by chunk with the streaming SVD (ooc_svd.h), on one process
// or, through a Collective, on many (btfc-mpi). Used by `btfc compress --max-memory` when the
// BTF does not fit, and by btfc-mpi always.
//
// Limits of this path (each reported as an error, not silently changed): color=rgb only (the
// dfmf channel transform is not streamed yet); svd=exact is refused (its m x m Gram matrix is the
// thing that does not fit); the factors are of the half-float working file, whose rounding
// (relative 2^-11 per value) is far below fmf's truncation error.
#pragma once
#include <memory>
#include <string>
#include <vector>

#include "codecs/codec.h"
#include "codecs/fmf/ooc_svd.h"
#include "formats/bonn/bdi_work.h"

namespace btfc {

// A BDI file as column chunks of the BTF matrix (rows = abrdf_size, one chunk per BDI chunk).
class BdiChunkSource final : public fmf::ChunkSource {
 public:
  explicit BdiChunkSource(const BdiChunks& f) : m_f(f) {}
  size_t rows() const override { return m_f.desc().abrdf_size(); }
  size_t num_chunks() const override { return m_f.num_chunks(); }
  size_t chunk_first(size_t c) const override { return m_f.chunk_first(c); }
  size_t chunk_count(size_t c) const override { return m_f.chunk_count(c); }
  size_t raw_bytes(size_t c) const override { return m_f.chunk_bytes(c); }
  Status read(size_t c, void* raw) const override { return m_f.read_raw(c, static_cast<uint16_t*>(raw)); }
  Status decode(size_t c, const void* raw, float* dst) const override {
    return m_f.decode(c, static_cast<const uint16_t*>(raw), dst);
  }
  // Mapped and decoded straight from the page cache: no raw half buffer.
  Status load(size_t c, void*, float* dst) const override { return m_f.read_decoded(c, dst); }
  size_t raw_buffer_bytes(size_t) const override { return 0; }

 private:
  const BdiChunks& m_f;
};

// Bytes the streaming SVD holds besides its chunk buffers (Y, Q, the sums, W^T, SxV) for a
// matrix of m rows, n texels and a sketch of l columns.
uint64_t streaming_fixed_bytes(uint64_t m, uint64_t n, uint64_t l);
// Bytes per matrix value the chunk buffers take (one raw half buffer + two float blocks): 10.
inline constexpr uint64_t k_stream_bytes_per_value = 10;
// Scan lines per working-file chunk so that the chunk buffers plus the fixed part fit in
// max_bytes; 0 when even one scan line does not fit. Capped at 256 MiB of float per chunk
// (bigger chunks gain nothing and leave fewer chunks to overlap reading with).
uint32_t stream_lines_per_chunk(const BtfDesc& desc, uint64_t l, size_t max_bytes);

// Checks the spec is one the streamed path supports (color=rgb, svd != exact); returns the
// sketch width l = rank + oversample.
Result<int> streaming_sketch_width(const Params& params);

struct StreamedEncode {
  std::unique_ptr<Model> model;  // process 0 only (null elsewhere)
  fmf::StreamStats stats;
  std::vector<size_t> chunks;    // the chunks this process read
};

// Factorizes `file`; `desc` is the BTF's description (the file's own, or the original input's,
// whose direction vectors are exact). `chunks` null = this process's share by coll.rank().
Result<StreamedEncode> encode_fmf_streamed(const BdiChunks& file, const BtfDesc& desc, const Params& params, Context& ctx,
                                           fmf::Collective& coll);
// The same from any chunk source of `desc`'s shape (e.g. a raw .btfc read in place,
// formats/btf_stream.h).
Result<StreamedEncode> encode_fmf_streamed(const fmf::ChunkSource& src, const BtfDesc& desc, const Params& params, Context& ctx,
                                           fmf::Collective& coll);

}  // namespace btfc
