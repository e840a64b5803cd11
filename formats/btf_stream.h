// Bounded-memory reading and writing of BTFs that do not fit in memory (`--max-memory`).
//
// prepare_work_file turns any input btfc reads into the working file the streamed fmf SVD
// reads chunk by chunk (an uncompressed Bonn BDI, formats/bonn/bdi_work.h), in one streaming
// pass that never holds more than the limit:
//   uncompressed BDI whose chunks fit   -> used as it is (no copy)
//   raw .btfc                           -> texel bands, CRC of the whole tensor verified
//   image set (formats/image_set.h)     -> groups of images (rows of B) scattered per texel
//   model .btfc / other Bonn files      -> decoded texel band by texel band
// The working file records its source (path, size, modification time) in its meta xml: an
// existing complete working file of the same source and chunking is reused, an incomplete one
// (interrupted run, see bdi_work.h) or one of another source is rebuilt, and says so in `note`.
// Values beyond the half range restart the pass with a power-of-two scale (bdi_work.h).
#pragma once
#include <string>

#include <memory>

#include "codecs/codec.h"
#include "core/chunks.h"
#include "core/btf.h"
#include "core/progress.h"
#include "formats/raw_btfc.h"
#include "formats/reader.h"

namespace btfc {

// The shape of the BTF at `path` without reading its values (any input read_btf takes).
Result<BtfDesc> probe_btf(const std::string& path);

struct WorkFile {
  std::string path;        // the BDI file to read
  bool built = false;      // written by this call (false: the input itself, or reused)
  bool reused = false;     // an existing working file of the same source was reused
  double seconds = 0;      // time of the building pass
  uint64_t bytes_written = 0;
  float scale = 1;
  std::string note;        // why a file at work_path was not reused, scale restarts, ...
};

// lines_per_chunk: texel rows per chunk of a newly built file (ooc_fmf.h sizes it);
// max_bytes bounds the buffers of the building pass. `input` is the opened input
// (formats/reader.h): its shape, image-set plan or model are used as they are, not probed again.
Result<WorkFile> prepare_work_file(BtfInput& input, const std::string& work_path, uint32_t lines_per_chunk, size_t max_bytes,
                                   Progress* progress);

// Decodes `model` band by band into an uncompressed BDI at `path` (written under a temporary
// name, renamed when complete), holding at most about max_bytes of decoded values.
Status decode_to_bdi(const Model& model, const std::string& path, size_t max_bytes);
// The same into a raw .btfc (float values, so HDR of any range): the container's data tensor is
// written band by band as the model decodes it, its CRC put into the chunk header last
// (core/container.h save_raw_btf_streamed).
Status decode_to_raw_btfc(const Model& model, const std::string& path, size_t max_bytes);

}  // namespace btfc

#include "core/metrics.h"
namespace btfc {
class BdiChunks;
// RMSE, relative L2, PSNR (peak rule of core/metrics.h) and max |error| of `model` against the
// BTF in `ref`, chunk by chunk; mean_ssim is NaN (SSIM needs whole images).
Result<Metrics> compare_streamed(const BdiChunks& ref, const Model& model);
// The same against any chunk source of whole texel rows (`path` names it in errors).
Result<Metrics> compare_streamed(const ChunkSource& ref, const BtfDesc& desc, const std::string& path, const Model& model);
}  // namespace btfc
