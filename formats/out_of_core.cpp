// compress_out_of_core (formats/out_of_core.h).
#include "formats/out_of_core.h"

#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <iostream>
#include <optional>

#include "core/memory.h"
#include "formats/bonn/bdi_work.h"
#include "formats/raw_btfc.h"

namespace btfc {
namespace {

double since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// A raw .btfc's chunks are mapped two at a time (8 bytes per value), and its pread fallback reads
// into two float blocks (8 too, since it reads straight into them). Sized for 12, what that
// fallback needed with its raw copy: kept, so the chunk plan (and with it the bits of every
// out-of-core encode) stays as measured in docs/benchmarks.md; a third of the limit is margin.
constexpr uint64_t k_in_place_bytes_per_value = 12;

}  // namespace

OutOfCoreResult::~OutOfCoreResult() {
  if (!temp_work.empty()) {
    std::error_code ec;
    std::filesystem::remove(temp_work, ec);
  }
}

OutOfCoreResult& OutOfCoreResult::operator=(OutOfCoreResult&& o) noexcept {
  if (this == &o) return *this;
  if (!temp_work.empty() && temp_work != o.temp_work) {
    std::error_code ec;
    std::filesystem::remove(temp_work, ec);
  }
  codec = o.codec, params = std::move(o.params), desc = std::move(o.desc), model = std::move(o.model);
  sizing = std::move(o.sizing), in_place = o.in_place, work = std::move(o.work);
  chunks = o.chunks, chunk_texels = o.chunk_texels, stats = std::move(o.stats), factorize_seconds = o.factorize_seconds;
  temp_work = std::move(o.temp_work);
  o.temp_work.clear();
  return *this;
}

std::string only_streaming_codecs() {
  std::string names;
  for (const Codec* c : all_codecs())
    if (c->streaming()) names += (names.empty() ? "" : ", ") + std::string(c->name());
  return names.empty() ? "no codec compresses out of core"
                       : "only " + names + (names.find(',') == std::string::npos ? " compresses" : " compress") + " out of core";
}

Result<OutOfCoreResult> compress_out_of_core(const OutOfCoreJob& job, Collective& coll) {
  const bool root = coll.rank() == 0;
  OutOfCoreResult r;
  const size_t limit = job.max_bytes;
  // The spec and the codec's plan: every process resolves them (they are pure functions).
  Status s = [&]() -> Status {
    BTFC_ASSIGN_OR_RETURN(auto resolved, resolve_spec(job.spec));
    r.codec = resolved.first, r.params = std::move(resolved.second);
    if (!r.codec->streaming())
      return invalid_argument(job.input + ": " + r.codec->name() + " needs the BTF in memory; " + only_streaming_codecs());
    return {};
  }();
  BTFC_RETURN_IF_ERROR(coll.agree(s));
  const StreamingEncoder& enc = *r.codec->streaming();

  // The input, opened at most once per process (the caller's, when it opened it already).
  std::unique_ptr<BtfInput> own;
  auto input = [&]() -> Result<BtfInput*> {
    if (job.opened) return job.opened;
    if (!own) {
      BTFC_ASSIGN_OR_RETURN(own, open_input(job.input));
    }
    return own.get();
  };
  auto shape = [&]() -> Result<BtfDesc> {
    BTFC_ASSIGN_OR_RETURN(BtfInput * in, input());
    return in->desc();
  };

  // In place: a raw .btfc every process sees, that fits the page cache, whose chunks fit.
  uint32_t raw_lines = 0;
  std::string why_work;
  const bool raw = job.opened ? !job.opened->model() && !job.opened->image_set_plan() : is_raw_btfc_file(job.input);
  if (job.work_file.empty() && raw) {
    auto d = shape();
    auto plan = d.ok() ? enc.plan(r.params, d.value(), limit) : Result<StreamSizing>(d.status());
    std::error_code ec;
    const uint64_t raw_bytes = std::filesystem::file_size(job.input, ec), avail = mem_available_bytes();
    if (!ec && avail > 0 && raw_bytes > avail)
      why_work = job.input + " (" + format_bytes(raw_bytes) + ") is larger than the available RAM (" + format_bytes(avail) +
                 "): a half-float working file halves the disk reads of every pass";
    else if (plan.ok()) {
      // The whole limit scaled by bytes_per_value / 12: the fixed part keeps its margin too.
      raw_lines = stream_lines_per_chunk(d.value(), plan.value(), limit / k_in_place_bytes_per_value * plan->bytes_per_value);
      r.desc = d.value();
      r.sizing = plan.value();  // in place only when every process got here (the vote below)
    }
  }
  double votes = raw_lines > 0 ? 1.0 : 0.0;
  BTFC_RETURN_IF_ERROR(coll.allreduce_sum(&votes, 1));
  r.in_place = votes == double(coll.size());

  // Otherwise process 0 prepares the working file; the others learn its path.
  std::string work_path;
  if (!r.in_place) {
    s = Status{};
    if (root) {
      s = [&]() -> Status {
        BTFC_ASSIGN_OR_RETURN(BtfInput * in, input());
        r.desc = in->desc();
        BTFC_ASSIGN_OR_RETURN(StreamSizing plan, enc.plan(r.params, r.desc, limit));
        const uint32_t lines = stream_lines_per_chunk(r.desc, plan, limit);
        if (lines == 0)
          return invalid_argument("--max-memory " + format_bytes(limit) + " is too small for " + r.desc.summary() +
                                  ": streaming needs at least " +
                                  format_bytes(plan.fixed_bytes + plan.bytes_per_value * r.desc.abrdf_size() * uint64_t(r.desc.width)));
        std::string work = job.work_file;
        if (work.empty()) {
          work = job.temp_dir + "/.btfc-work-" + std::to_string(::getpid()) + ".btf";
          r.temp_work = work;
        }
        BTFC_ASSIGN_OR_RETURN(r.work, prepare_work_file(*in, work, lines, limit, job.progress));
        if (r.work.path != work) r.temp_work.clear();  // the input itself is the working file
        if (!why_work.empty()) r.work.note = why_work + (r.work.note.empty() ? "" : "; " + r.work.note);
        if (!r.work.note.empty() && job.notes) std::cerr << "note: " << r.work.note << "\n";
        return {};
      }();
      work_path = r.work.path;
    }
    BTFC_RETURN_IF_ERROR(coll.agree(s));
    BTFC_RETURN_IF_ERROR(coll.broadcast(work_path));
  }

  // Every process opens its source.
  std::unique_ptr<ChunkSource> src;
  std::optional<BdiChunks> file;
  s = [&]() -> Status {
    if (r.in_place) {
      BTFC_ASSIGN_OR_RETURN(src, open_raw_chunks(job.input, raw_lines));
      r.work.path = job.input;
      r.work.note = "raw .btfc streamed in place (texel-major already): no working file";
      return {};
    }
    BTFC_ASSIGN_OR_RETURN(BdiChunks f, BdiChunks::open(work_path));
    file.emplace(std::move(f));
    if (!root) r.desc = file->desc();
    if (file->desc().abrdf_size() != r.desc.abrdf_size() || file->desc().num_texels() != r.desc.num_texels())
      return invalid_argument(file->path() + ": working file shape (" + file->desc().summary() + ") differs from the BTF's (" +
                              r.desc.summary() + ")");
    BTFC_ASSIGN_OR_RETURN(r.sizing, enc.plan(r.params, r.desc, limit));
    const uint64_t buffers = r.sizing.bytes_per_value * r.desc.abrdf_size() * file->chunk_count(0);
    if (buffers + r.sizing.fixed_bytes > limit)
      return invalid_argument(file->path() + ": its chunks of " + std::to_string(file->chunk_count(0)) + " texels need " +
                              format_bytes(buffers) + " of buffers, more than --max-memory " + format_bytes(limit));
    src = std::make_unique<BdiChunkSource>(*file);
    return {};
  }();
  BTFC_RETURN_IF_ERROR(coll.agree(s));
  r.chunks = src->num_chunks(), r.chunk_texels = src->chunk_count(0);

  Context ctx;
  ctx.seed = job.seed;
  ctx.progress = job.progress;
  ctx.max_bytes = limit;
  const auto t0 = std::chrono::steady_clock::now();
  auto out = enc.encode(*src, r.desc, r.params, ctx, coll);
  BTFC_RETURN_IF_ERROR(coll.agree(out.ok() ? Status{} : out.status()));  // the passes' own failures are agreed already
  r.factorize_seconds = since(t0);
  r.model = std::move(out->model);
  r.stats = std::move(out->stats);
  return r;
}

}  // namespace btfc
