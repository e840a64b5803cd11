// Out of core: encoding a BTF that is never held whole, from column chunks of its matrix
// (core/chunks.h), on one process or on many that share the passes through a Collective.
//
// A codec that can do this returns a StreamingEncoder from Codec::streaming() (null for the
// others). Everything around it - when to stream, where the chunks come from (a raw .btfc read
// in place or a half-float working file), naming and cleaning the working file, MPI agreement -
// is one library call, formats/out_of_core.h compress_out_of_core, used by both `btfc compress
// --max-memory` and btfc-mpi; neither names a codec.
#pragma once
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "codecs/codec.h"
#include "core/chunks.h"

namespace btfc {

// Per-process measurements of one streamed encode (summed over its factorizations).
struct StreamStats {
  int passes = 0;
  uint64_t bytes_read = 0;            // raw chunk bytes this process read
  std::vector<double> pass_seconds;   // wall time of each pass (including its collective sum)
  double reduce_seconds = 0;          // time inside allreduce_sum / reduce_sum_to_root
  uint64_t reduce_bytes = 0;          // payload of the collective sums (per process)
  uint64_t buffer_bytes = 0;          // chunk buffers allocated (the largest of the factorizations)
};

// What a streamed encode of a spec needs, for sizing the chunks.
struct StreamSizing {
  int passes = 0;                 // passes over the chunks in all
  uint64_t fixed_bytes = 0;       // memory besides the chunk buffers
  uint64_t bytes_per_value = 10;  // chunk buffer bytes per value of a chunk (see the codec's plan)
  std::string note;               // how the spec resolved out of core, when that differs from in core
};

struct StreamedEncode {
  std::unique_ptr<Model> model;  // process 0 only (null elsewhere)
  StreamStats stats;
  std::vector<size_t> chunks;    // the chunks this process read
};

class StreamingEncoder {
 public:
  virtual ~StreamingEncoder() = default;
  // Checks that `params` stream on `desc` within max_bytes per process (an error names what does
  // not fit) and says what the encode needs.
  virtual Result<StreamSizing> plan(const Params& params, const BtfDesc& desc, size_t max_bytes) const = 0;
  // Encodes from `src` (rows = desc.abrdf_size(), one column per texel); each process reads the
  // chunks owned_chunks(src, coll.rank(), coll.size()) gives it. `desc` is the original input's
  // (its direction vectors are exact). Within ctx.max_bytes per process.
  virtual Result<StreamedEncode> encode(const ChunkSource& src, const BtfDesc& desc, const Params& params, Context& ctx,
                                        Collective& coll) const = 0;
};

// Scan lines per chunk so that the chunk buffers plus sizing.fixed_bytes fit in max_bytes; 0 when
// even one scan line does not fit. Capped at 256 MiB of float per chunk (bigger chunks gain
// nothing and leave fewer chunks to overlap reading with).
uint32_t stream_lines_per_chunk(const BtfDesc& desc, const StreamSizing& sizing, size_t max_bytes);

}  // namespace btfc
