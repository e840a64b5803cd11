// The fmf codec out of core: factorizes a BTF read chunk by chunk (any core/chunks.h source: an
// uncompressed Bonn BDI working file, formats/bonn/bdi_work.h, or a raw .btfc read in place)
// with the streamed SVDs (ooc_svd.h), on one process or, through a Collective, on many
// (btfc-mpi). Used by `btfc compress --max-memory` when the BTF does not fit, and by btfc-mpi
// always.
//
// Every fmf option streams:
//   color=rgb   one factorization of the BTF matrix (rows = abrdf_size);
//   color=dfmf  three, one per channel matrix (Y', U', V'; rows = num_images): randomized, all
//               three in one stream (dfmf_streaming_svds, ooc_dfmf.h: each pass reads the BTF
//               once); exact, one after the other, each a DfmfChannelSource over the same
//               chunks (three times the passes);
//   svd=exact   the two-pass Gram method (streaming_exact_svd) when its rows x rows Gram matrix
//               and the solver's workspace fit the limit, else an error naming the sizes;
//   svd=auto    exact when rows <= 1024 (in core: min(rows, texels) <= 1024; only the rows side
//               streams) and it fits, else randomized; svd=randomized with rank + oversample >=
//               rows is exact too, as in core.
// The factors are of the chunk source's values: for a half-float working file its rounding
// (relative 2^-11 per value) is far below fmf's truncation error.
#pragma once
#include <memory>
#include <string>
#include <vector>

#include "codecs/codec.h"
#include "codecs/streaming.h"
#include "codecs/fmf/ooc_svd.h"

namespace btfc {

// Bytes per value of a chunk of the BTF matrix the chunk buffers take: one raw half buffer + two
// float blocks (10). dfmf takes no more: a float scratch of the base chunk + two channel blocks
// a third its size (6.7) + the base's raw buffer (a BDI file's chunks are mapped: 0; the pread
// fallback of a raw .btfc, a float copy: 10.7, within the 12 the CLI budgets for that source).
inline constexpr uint64_t k_stream_bytes_per_value = 10;

// How the streamed encode of a spec runs on a BTF (what fmf's options resolve to out of core).
struct StreamPlan {
  bool dfmf = false;
  bool exact = false;        // every block by streaming_exact_svd (2 passes), else streaming_svd
  uint64_t rows = 0;         // rows of each factorized matrix: abrdf_size, or num_images (dfmf)
  uint64_t l = 0;            // randomized sketch width: max rank + oversample, <= min(rows, texels)
  int kept_blocks = 1;       // randomized: Krylov blocks (of at most l) held at once (streaming_svd's kept_blocks)
  bool sketch_sums = false;  // randomized: the first pass sums B S over the chunks (SvdOptions::sketch_sums)
  int passes = 0;            // passes over the chunks in all (exact dfmf: x 3)
  uint64_t fixed_bytes = 0;  // memory besides the chunk buffers (Gram or sketch, SxV, finished blocks)
  uint64_t bytes_per_value = k_stream_bytes_per_value;  // of a chunk: its buffers (+ 4 for dfmf's split parts)
  std::string note;          // set when svd=auto or randomized resolved differently than in core
};
// Checks the spec streams within max_bytes (svd=exact whose Gram matrix does not fit is an
// error naming the sizes) and resolves it.
Result<StreamPlan> plan_streamed_fmf(const Params& params, const BtfDesc& desc, size_t max_bytes);
// The plan as the generic sizing (codecs/streaming.h).
StreamSizing stream_sizing(const StreamPlan& plan);
// fmf's Codec::streaming(): plan_streamed_fmf + encode_fmf_streamed.
const StreamingEncoder& fmf_streaming();

// Factorizes the chunk source `src` of `desc`'s shape (`desc` is the original input's, whose
// direction vectors are exact). Each process reads its share of the chunks by coll.rank(); the
// plan is made against ctx.max_bytes (per process).
Result<StreamedEncode> encode_fmf_streamed(const ChunkSource& src, const BtfDesc& desc, const Params& params, Context& ctx,
                                           Collective& coll);

}  // namespace btfc
