// fmf out of core; see ooc_fmf.h.
#include "codecs/fmf/ooc_fmf.h"

#include <algorithm>

#include "codecs/fmf/fmf.h"

namespace btfc {

uint64_t streaming_fixed_bytes(uint64_t m, uint64_t n, uint64_t l) {
  // Y (double) + the allreduce buffer (double) + Q, Z, Yf (float) on m rows; W^T, SxV (float)
  // and the Gaussian rows on n texels; a 16 MiB allowance for the small matrices and stacks.
  return m * l * (8 + 8 + 4 + 4 + 4) + n * l * (4 + 4) + (uint64_t(16) << 20);
}

uint32_t stream_lines_per_chunk(const BtfDesc& desc, uint64_t l, size_t max_bytes) {
  const uint64_t m = desc.abrdf_size(), fixed = streaming_fixed_bytes(m, desc.num_texels(), l);
  if (fixed >= max_bytes) return 0;
  const uint64_t per_line = k_stream_bytes_per_value * m * uint64_t(desc.width);
  uint64_t lines = (max_bytes - fixed) / per_line;
  const uint64_t cap = std::max<uint64_t>(1, (uint64_t(64) << 20) / (m * uint64_t(desc.width)));  // 64 M floats = 256 MiB
  lines = std::min({lines, cap, uint64_t(desc.height)});
  return uint32_t(lines);
}

Result<int> streaming_sketch_width(const Params& p) {
  if (p.get("color") != "rgb")
    return unsupported("fmf out of core: color=" + p.get("color") + " is not streamed (only color=rgb); give more --max-memory to run it in core");
  if (p.get("svd") == "exact")
    return unsupported("fmf out of core: svd=exact needs the rows x rows Gram matrix in memory; use svd=auto or randomized");
  return int(p.get_int("rank") + p.get_int("oversample"));
}

Result<StreamedEncode> encode_fmf_streamed(const BdiChunks& file, const BtfDesc& desc, const Params& p, Context& ctx,
                                           fmf::Collective& coll) {
  BTFC_RETURN_IF_ERROR(streaming_sketch_width(p).status());
  if (desc.abrdf_size() != file.desc().abrdf_size() || desc.num_texels() != file.desc().num_texels())
    return invalid_argument(file.path() + ": working file shape (" + file.desc().summary() + ") differs from the BTF's (" + desc.summary() + ")");
  BdiChunkSource src(file);
  return encode_fmf_streamed(src, desc, p, ctx, coll);
}

Result<StreamedEncode> encode_fmf_streamed(const fmf::ChunkSource& src, const BtfDesc& desc, const Params& p, Context& ctx,
                                           fmf::Collective& coll) {
  BTFC_RETURN_IF_ERROR(streaming_sketch_width(p).status());
  if (src.rows() != desc.abrdf_size() || src.texels() != desc.num_texels())
    return invalid_argument("fmf out of core: the chunk source's shape differs from the BTF's (" + desc.summary() + ")");
  fmf::SvdOptions opt;
  opt.max_rank = int(p.get_int("rank"));
  opt.target_rel_error = p.get_real("target_error");
  opt.oversample = int(p.get_int("oversample"));
  opt.power_iters = int(p.get_int("power_iters"));
  opt.seed = ctx.seed;
  opt.progress = coll.rank() == 0 ? ctx.progress : nullptr;
  StreamedEncode out;
  out.chunks = fmf::owned_chunks(src, coll.rank(), coll.size());
  BTFC_ASSIGN_OR_RETURN(fmf::SvdResult r, fmf::streaming_svd(src, out.chunks, opt, coll, &out.stats));
  if (coll.rank() != 0) return out;
  ModelStats stats;
  stats.add("stream.passes", out.stats.passes);
  stats.add("stream.processes", coll.size());
  stats.add("stream.chunks", double(src.num_chunks()));
  stats.add("stream.bytes_read", double(out.stats.bytes_read));
  stats.add("stream.buffer_bytes", double(out.stats.buffer_bytes));
  double total = 0;
  for (double s : out.stats.pass_seconds) total += s;
  stats.add("stream.pass_seconds", total);
  stats.add("stream.reduce_seconds", out.stats.reduce_seconds);
  BTFC_ASSIGN_OR_RETURN(out.model, make_fmf_model_from_svd(desc, p, std::move(r), std::move(stats)));
  return out;
}

}  // namespace btfc
