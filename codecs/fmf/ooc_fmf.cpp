// fmf out of core; see ooc_fmf.h.
#include "codecs/fmf/ooc_fmf.h"

#include <algorithm>
#include <chrono>

#include "codecs/fmf/fmf.h"
#include "codecs/fmf/ooc_dfmf.h"
#include "core/memory.h"

namespace btfc {
namespace {

// Adds one factorization's measurements to the encode's.
void add_stats(StreamStats& sum, StreamStats one) {
  sum.passes += one.passes;
  sum.bytes_read += one.bytes_read;
  sum.pass_seconds.insert(sum.pass_seconds.end(), one.pass_seconds.begin(), one.pass_seconds.end());
  sum.reduce_seconds += one.reduce_seconds;
  sum.reduce_bytes += one.reduce_bytes;
  sum.buffer_bytes = std::max(sum.buffer_bytes, one.buffer_bytes);
}

}  // namespace

Result<StreamPlan> plan_streamed_fmf(const Params& p, const BtfDesc& desc, size_t max_bytes) {
  StreamPlan plan;
  plan.dfmf = p.get("color") == "dfmf";
  if (plan.dfmf && desc.channels != 3)
    return invalid_argument("fmf: color=dfmf needs 3 channels, the BTF has " + std::to_string(desc.channels));
  plan.rows = plan.dfmf ? desc.num_images() : desc.abrdf_size();
  const uint64_t m = plan.rows, n = desc.num_texels();
  const uint64_t rank = uint64_t(p.get_int("rank")), chroma = p.get_int("chroma_rank") ? uint64_t(p.get_int("chroma_rank")) : rank;
  const uint64_t max_rank = plan.dfmf ? std::max(rank, chroma) : rank;
  plan.l = std::min({m, n, max_rank + uint64_t(p.get_int("oversample"))});
  // The in-core choice (svd.cpp, truncated_svd) with the rows side for its small side: the Gram
  // matrix of the texel side would need every pair of chunks at once.
  const std::string svd = p.get("svd");
  plan.exact = svd == "exact" || (svd == "auto" && m <= 1024) || max_rank + uint64_t(p.get_int("oversample")) >= m;
  if (!plan.exact && svd == "auto" && std::min(m, n) <= 1024)
    plan.note = "svd=auto: randomized (in core exact through the texels x texels Gram matrix, which does not stream)";
  // Exact dfmf factorizes one channel after the other: finished blocks wait for the model while
  // the next channel runs (y and u during v). Randomized dfmf runs the three in one stream.
  const uint64_t finished = plan.dfmf ? n * 4 * (rank + chroma) : 0, base = uint64_t(16) << 20;
  const uint64_t channels = plan.dfmf ? 3 : 1;
  // The randomized dfmf stream's split parts (ooc_svd.h) hold at most a chunk's values as floats.
  plan.bytes_per_value = k_stream_bytes_per_value + (plan.dfmf ? 4 : 0);
  // Randomized (block Krylov, ooc_svd.h), keeping k blocks of at most l (width w <= k l: from
  // q 2 on the later blocks are rank wide, svd.h later_krylov_width; the plan counts k l), per
  // channel: on the rows the basis P (double) and, in the passes, the sum buffer (double), Q and B Z (float);
  // on the texels W^T (w, float) and SxV or the first pass's test matrix (l: the dense Gaussian
  // rows, or the sparse sketch's scratch, svd.h column_sketch_bytes, which is at most as large);
  // with plan.sketch_sums the sparse sketch's sums over the chunks (svd.h column_sketch_sums_bytes:
  // m x s floats, s ~ 4 l); the Gram matrices; 16 MiB for small matrices and stacks.
  const uint64_t sums_bytes = column_sketch_sums_bytes(m, n, Eigen::Index(plan.l));
  auto randomized_bytes = [&](uint64_t k) {
    const uint64_t width = k * plan.l, sums = plan.sketch_sums ? sums_bytes : 0;
    return channels * (m * (8 * width + 16 * plan.l) + n * (width + plan.l) * 4 + sums + width * width * 8 * 3) + base;
  };
  // All q + 1 blocks when the chunks keep at least half the scan lines they have with one block
  // (the power iteration's footprint); else as many as do (a full basis then restarts from its
  // Ritz vectors, ooc_svd.h).
  const uint64_t max_blocks = std::max<uint64_t>(1, std::min<uint64_t>(uint64_t(p.get_int("power_iters")) + 1, std::min(m, n) / plan.l));
  auto lines = [&](uint64_t k) {
    StreamSizing z;
    z.fixed_bytes = randomized_bytes(k), z.bytes_per_value = plan.bytes_per_value;
    return stream_lines_per_chunk(desc, z, max_bytes);
  };
  // The sketch's sums (one W G per stream instead of one per chunk: 0.72-0.75 -> 0.42-0.44 s for
  // the first pass at rank 128, UBO2003 size, docs/benchmarks.md) when the chunks keep at least
  // half the scan lines they have without them.
  if (sums_bytes > 0) {
    const uint32_t without = lines(1);
    plan.sketch_sums = true;
    if (lines(1) < std::max<uint32_t>(1, without / 2)) plan.sketch_sums = false;
  }
  const uint32_t floor_lines = std::max<uint32_t>(1, lines(1) / 2);
  plan.kept_blocks = 1;
  for (uint64_t k = max_blocks; k > 1; --k)
    if (lines(k) >= floor_lines) {
      plan.kept_blocks = int(k);
      break;
    }
  const uint64_t randomized = randomized_bytes(uint64_t(plan.kept_blocks));
  const uint64_t exact = fmf::streaming_exact_bytes(m) + n * max_rank * 4 + finished + base;  // + SxV
  // Only the Gram part is the exact path's own; when the factors (texel side, needed by either
  // path) do not fit, the caller's chunk sizing reports the whole need.
  const uint64_t gram = fmf::streaming_exact_bytes(m) + (uint64_t(16) << 20);
  if (plan.exact && gram > max_bytes) {
    const std::string what = std::to_string(m) + " x " + std::to_string(m) + " Gram matrix (" + format_bytes(m * m * 8) +
                             " of double; " + format_bytes(gram) + " with the eigen-solver's workspace)";
    if (svd == "exact")
      return invalid_argument("fmf out of core: svd=exact needs the " + what + ", more than --max-memory " + format_bytes(max_bytes) +
                              "; use svd=randomized or give more memory");
    plan.exact = false;
    plan.note = "svd=" + svd + ": randomized, the exact path's " + what + " does not fit " + format_bytes(max_bytes);
  }
  plan.fixed_bytes = plan.exact ? exact : randomized;
  plan.passes = plan.exact ? 2 * int(channels) : int(max_blocks) + 1;  // at most: Krylov may stop early
  return plan;
}

StreamSizing stream_sizing(const StreamPlan& plan) {
  StreamSizing z;
  z.passes = plan.passes, z.fixed_bytes = plan.fixed_bytes, z.bytes_per_value = plan.bytes_per_value, z.note = plan.note;
  return z;
}

namespace {
class FmfStreaming final : public StreamingEncoder {
 public:
  Result<StreamSizing> plan(const Params& p, const BtfDesc& desc, size_t max_bytes) const override {
    BTFC_ASSIGN_OR_RETURN(StreamPlan plan, plan_streamed_fmf(p, desc, max_bytes));
    return stream_sizing(plan);
  }
  Result<StreamedEncode> encode(const ChunkSource& src, const BtfDesc& desc, const Params& p, Context& ctx,
                                Collective& coll) const override {
    return encode_fmf_streamed(src, desc, p, ctx, coll);
  }
};
}  // namespace

const StreamingEncoder& fmf_streaming() {
  static const FmfStreaming s;
  return s;
}

Result<StreamedEncode> encode_fmf_streamed(const ChunkSource& src, const BtfDesc& desc, const Params& p, Context& ctx,
                                           Collective& coll) {
  BTFC_ASSIGN_OR_RETURN(StreamPlan plan, plan_streamed_fmf(p, desc, ctx.max_bytes));
  if (src.rows() != desc.abrdf_size() || src.texels() != desc.num_texels())
    return invalid_argument("fmf out of core: the chunk source's shape differs from the BTF's (" + desc.summary() + ")");
  SvdOptions opt;
  opt.target_rel_error = p.get_real("target_error");
  opt.oversample = int(p.get_int("oversample"));
  opt.power_iters = int(p.get_int("power_iters"));
  opt.seed = ctx.seed;
  opt.sketch_sums = plan.sketch_sums;
  opt.progress = coll.rank() == 0 ? ctx.progress : nullptr;
  StreamedEncode out;
  out.chunks = owned_chunks(src, coll.rank(), coll.size());
  auto factor = [&](const ChunkSource& s, int max_rank) -> Result<SvdResult> {
    opt.max_rank = max_rank;
    StreamStats st;
    auto r = plan.exact ? fmf::streaming_exact_svd(s, out.chunks, opt, coll, &st) : fmf::streaming_svd(s, out.chunks, opt, coll, &st, plan.kept_blocks);
    add_stats(out.stats, std::move(st));
    return r;
  };
  const int rank = int(p.get_int("rank")), chroma = int(p.get_int("chroma_rank"));
  std::vector<SvdResult> rs;
  double clamped = 0;
  Params rp = p;  // dfmf: with the resolved offset (the model's spec)
  float offset = 0;
  double offset_seconds = 0;
  if (plan.dfmf) {
    double e = p.get_real("offset");
    if (e <= 0) {
      const auto t0 = std::chrono::steady_clock::now();
      BTFC_ASSIGN_OR_RETURN(e, DfmfChannelSource::auto_offset(src, out.chunks, coll));
      offset_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    }
    BTFC_ASSIGN_OR_RETURN(rp, dfmf_with_offset(p, e));
    offset = float(rp.get_real("offset"));
    if (opt.target_rel_error > 0)
      return unsupported("fmf: color=dfmf with target_error (the error of the decoded data) needs the BTF in memory; raise --max-memory or set rank");
  }
  if (!plan.dfmf) {
    BTFC_ASSIGN_OR_RETURN(SvdResult r, factor(src, rank));
    rs.push_back(std::move(r));
  } else {
    if (plan.exact) {
      for (int k = 0; k < 3; ++k) {
        const DfmfChannelSource channel(src, k, offset);
        BTFC_ASSIGN_OR_RETURN(SvdResult r, factor(channel, k == 0 ? rank : (chroma ? chroma : rank)));
        rs.push_back(std::move(r));
        if (k == 0) clamped = double(channel.clamped());
      }
    } else {
      SvdOptions oy = opt, oc = opt;
      oy.max_rank = rank, oc.max_rank = chroma ? chroma : rank;
      StreamStats st;
      auto r = dfmf_streaming_svds(src, out.chunks, offset, oy, oc, coll, &st, plan.kept_blocks, &clamped);
      add_stats(out.stats, std::move(st));
      if (!r.ok()) return r.status();
      rs = std::move(r).value();
    }
    // Each process counted its own chunks; every process gets here (SVD failures are agreed).
    BTFC_RETURN_IF_ERROR(coll.allreduce_sum(&clamped, 1));
  }
  if (coll.rank() != 0) return out;
  ModelStats stats;
  if (plan.dfmf) {
    stats.add("negative_luminance_clamped", clamped);
    stats.add("dfmf_offset", offset);
    if (offset_seconds > 0) stats.add("stream.offset_pass_seconds", offset_seconds);
  }
  if (!plan.note.empty()) stats.note("stream.svd", plan.note);
  stats.add("stream.passes", out.stats.passes);
  stats.add("stream.processes", coll.size());
  stats.add("stream.chunks", double(src.num_chunks()));
  stats.add("stream.bytes_read", double(out.stats.bytes_read));
  stats.add("stream.buffer_bytes", double(out.stats.buffer_bytes));
  double total = 0;
  for (double s : out.stats.pass_seconds) total += s;
  stats.add("stream.pass_seconds", total);
  stats.add("stream.reduce_seconds", out.stats.reduce_seconds);
  auto model = plan.dfmf ? make_dfmf_model_from_svd(desc, rp, std::move(rs[0]), std::move(rs[1]), std::move(rs[2]), std::move(stats))
                         : make_fmf_model_from_svd(desc, p, std::move(rs[0]), std::move(stats));
  if (!model.ok()) return model.status();
  out.model = std::move(model).value();
  return out;
}

}  // namespace btfc
