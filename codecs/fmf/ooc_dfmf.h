// color=dfmf out of core: the channel matrices of Bonn's DFMF colour model (log luminance Y',
// chroma ratios U', V'; rows = num_images, fmf.h) as chunk sources over a source of the BTF
// matrix (rows = num_images x 3, RGB fastest), so the streamed SVDs (ooc_svd.h) factorize each
// channel without the channel matrix ever existing whole. Each chunk is the base chunk run
// through dfmf_channel (fmf.h), the transform the in-core encode uses, texel by texel.
//
// Memory per chunk: the base chunk (mapped when the base is mappable, else loaded through the
// base's load() into a float scratch that, with the base's raw buffer, lives in the raw buffer
// streaming_svd allocates for this source) plus the two channel blocks streaming_svd holds:
// base chunk values x (4 + 8/3 [+ the base's raw bytes]) bytes, within the 10 bytes per value
// ooc_fmf.h budgets for a chunk of the base.
//
// Loads run on one helper thread at a time (ooc_pass.h); several channel sources over the same
// base may exist, they share nothing but the base.
#pragma once
#include <atomic>
#include <memory>
#include <vector>

#include "codecs/fmf/ooc_svd.h"

namespace btfc {

class DfmfChannelSource final : public ChunkSource {
 public:
  // Channel k (0: Y', 1: U', 2: V') of `base` with luminance offset `offset` (fmf.h), whose
  // rows must be a multiple of 3.
  DfmfChannelSource(const ChunkSource& base, int k, float offset);
  size_t rows() const override { return m_base.rows() / 3; }
  size_t num_chunks() const override { return m_base.num_chunks(); }
  size_t chunk_first(size_t c) const override { return m_base.chunk_first(c); }
  size_t chunk_count(size_t c) const override { return m_base.chunk_count(c); }
  size_t raw_bytes(size_t c) const override { return m_base.raw_bytes(c); }
  // read(): the base's raw bytes; decode(): the base's decode into a temporary float chunk, then
  // the transform. load() (what the SVDs call) avoids the temporary: see the header comment.
  Status read(size_t c, void* raw) const override { return m_base.read(c, raw); }
  Status decode(size_t c, const void* raw, float* dst) const override;
  Status load(size_t c, void* raw, float* dst) const override;
  size_t raw_buffer_bytes(size_t c) const override;
  // The base's whole-file check (a raw .btfc's CRC), after the first pass of every channel's SVD
  // (the base's check is idempotent: the same answer each time).
  Status finish_first_pass(Collective& coll) const override { return m_base.finish_first_pass(coll); }

  // Luminance values clamped to 0 over the chunks loaded so far, each chunk counted once however
  // often it was loaded (channel 0 only counts; the other channels clamp the same values).
  uint64_t clamped() const;

  // The automatic offset (offset=0; dfmf_offset_sample, fmf.h) of `base`: the sums of the
  // sample texels in `chunks`, joined over the processes of `coll` (every process gets the same
  // e, the in-core encode's bits), in one sweep of the chunks before the factorizations, which
  // is also their first sight (the base's checks, which name a non-finite value).
  static Result<double> auto_offset(const ChunkSource& base, const std::vector<size_t>& chunks, Collective& coll);

 private:
  Status transform(size_t c, const float* base_chunk, float* dst) const;
  static size_t scratch_bytes(size_t values);

  const ChunkSource& m_base;
  int m_k;
  float m_offset;
  std::unique_ptr<std::atomic<uint64_t>[]> m_clamped;  // per chunk; set (not added) by every load
};

// The three channel matrices of `base` (rows = 3 x num_images) factorized in one stream
// (fmf::streaming_svds): each pass converts every part of a chunk once into Y', U', V'
// (dfmf_channels, in parallel over texels) and runs each channel's products on it, so a pass
// reads the BTF once for all three (DfmfChannelSource: once per channel). opt_y for Y', opt_c for
// U' and V'. Adds to *clamped the luminance values clamped in this process's chunks (each
// counted once). Besides streaming_svd's memory per channel, the parts take at most a chunk's
// values in floats. With `in_place`, the writable memory `base` maps (its values, column-major
// rows x texels, as MatrixChunks over an in-memory BTF) whose values the caller no longer needs:
// each texel's column is converted once, in the first pass, into its Y', U' and V' columns one
// after the other, and the passes read the channels there (ChunkSplit::in_place; no parts are
// held). The same results, bit for bit.
Result<std::vector<SvdResult>> dfmf_streaming_svds(const ChunkSource& base, const std::vector<size_t>& chunks, float offset,
                                                   const SvdOptions& opt_y, const SvdOptions& opt_c, Collective& coll,
                                                   StreamStats* stats, int kept_blocks, double* clamped, float* in_place = nullptr);

}  // namespace btfc
