// compress_out_of_core: the one library call behind `btfc compress --max-memory` (when the BTF
// does not fit) and `btfc-mpi compress`. It asks the codec whether it streams
// (Codec::streaming(), codecs/streaming.h), sizes the chunks for the limit, picks where they
// come from, and runs the streamed encode on every process of `coll`:
//   - a raw .btfc is streamed in place (its tensor is texel-major already) when every process
//     can map its chunks within the limit and the file fits the page cache (beyond the available
//     RAM every pass reads the disk, and a half-float working file halves those bytes);
//   - otherwise process 0 builds (or reuses) a half-float BDI working file
//     (formats/btf_stream.h prepare_work_file) named `work_file`, or
//     `<temp_dir>/.btfc-work-<pid>.btf` (removed when the result is destroyed, and by the CLI's
//     interrupt cleanup, cli/outputs.h), and every process reads its own chunks of it.
// Every failure is agreed on by all processes (Collective::agree): all return the same error.
#pragma once
#include <memory>
#include <string>

#include "codecs/codec.h"
#include "codecs/streaming.h"
#include "core/chunks.h"
#include "core/progress.h"
#include "formats/btf_stream.h"
#include "formats/reader.h"

namespace btfc {

struct OutOfCoreJob {
  std::string input;
  std::string spec;
  size_t max_bytes = 0;   // per process
  uint64_t seed = 1;
  std::string work_file;  // empty: automatic (see above)
  std::string temp_dir;   // where an automatic working file goes
  Progress* progress = nullptr;
  bool notes = true;      // print "note: ..." lines about the working file on stderr (process 0)
  // The input as the caller opened it (formats/reader.h), or null: then it is opened here, once,
  // by the processes that need its shape. Either way it is probed and opened once.
  BtfInput* opened = nullptr;
};

struct OutOfCoreResult {
  OutOfCoreResult() = default;
  // Moves hand the working file over: only one object removes it.
  OutOfCoreResult(OutOfCoreResult&& o) noexcept { *this = std::move(o); }
  OutOfCoreResult& operator=(OutOfCoreResult&& o) noexcept;
  ~OutOfCoreResult();      // removes an automatic working file (process 0)

  const Codec* codec = nullptr;
  Params params;
  BtfDesc desc;
  std::unique_ptr<Model> model;  // process 0 only
  StreamSizing sizing;
  bool in_place = false;   // the raw .btfc input itself was streamed
  WorkFile work;           // the working file (in place: path = the input, note says so)
  size_t chunks = 0, chunk_texels = 0;
  StreamStats stats;       // this process's
  double factorize_seconds = 0;
  std::string temp_work;   // an automatic working file to remove
};

// "only fmf compresses out of core": the registry's codecs that stream, for error messages.
std::string only_streaming_codecs();

Result<OutOfCoreResult> compress_out_of_core(const OutOfCoreJob& job, Collective& coll);

}  // namespace btfc
