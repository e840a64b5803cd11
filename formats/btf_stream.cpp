// Bounded-memory BTF input / output; see btf_stream.h.
#include "formats/btf_stream.h"
#include "formats/reader.h"

#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <future>

#include "core/container.h"
#include "formats/bonn/bdi_work.h"
#include "formats/bonn/bonn_btf.h"
#include "formats/btf_io.h"
#include "formats/image_set.h"

namespace btfc {
namespace {

namespace fs = std::filesystem;

// "source=... bytes=... mtime=...": identifies the input a working file was made from.
std::string fingerprint(const std::string& input) {
  std::error_code ec;
  const std::string abs = fs::absolute(input, ec).lexically_normal().string();
  uint64_t bytes = 0, count = 0;
  int64_t mtime = 0;
  auto add = [&](const fs::path& p) {
    struct stat st {};
    if (::stat(p.c_str(), &st) == 0) {
      bytes += uint64_t(st.st_size), ++count;
      mtime = std::max<int64_t>(mtime, int64_t(st.st_mtim.tv_sec) * 1000000000 + st.st_mtim.tv_nsec);
    }
  };
  if (fs::is_directory(input, ec)) {
    for (auto it = fs::recursive_directory_iterator(input, ec); !ec && it != fs::recursive_directory_iterator(); it.increment(ec))
      if (it->is_regular_file(ec)) add(it->path());
  } else {
    add(input);
  }
  std::string q;  // xml attribute value: escape what would end it
  for (char c : abs) q += c == '"' ? std::string("&quot;") : c == '&' ? std::string("&amp;") : c == '<' ? std::string("&lt;") : std::string(1, c);
  return "source=\"" + q + "\" source_bytes=\"" + std::to_string(bytes) + "\" source_files=\"" + std::to_string(count) +
         "\" source_mtime=\"" + std::to_string(mtime) + "\"";
}

// Rows of texels per band for `bytes_per_value` bytes of buffer per value within max_bytes.
uint64_t band_lines(const BtfDesc& d, uint64_t bytes_per_value, size_t max_bytes) {
  const uint64_t per_line = bytes_per_value * d.abrdf_size() * uint64_t(d.width);
  return std::clamp<uint64_t>(max_bytes / per_line, 1, uint64_t(d.height));
}

// One attempt at filling `w` from the input; an overflow (w.overflow() > 0) asks for a retry.
Status fill(BtfInput& in, BdiWriter& w, const BtfDesc& d, size_t max_bytes, Progress* progress) {
  const std::string& input = in.path();
  const uint64_t texels = d.num_texels(), width = uint64_t(d.width);
  if (const ImageSetPlan* planned = in.image_set_plan()) {
    const ImageSetPlan& plan = *planned;
    const uint64_t img_bytes = texels * uint64_t(d.channels) * 4;
    // Decoded images (float) + their half segments; OIIO's own per-image buffers come on top.
    const uint64_t k = std::clamp<uint64_t>(max_bytes / 2 / img_bytes, 1, d.num_images());
    std::vector<float> buf(k * texels * uint64_t(d.channels));
    if (progress) progress->start("working file (image groups)", (d.num_images() + k - 1) / k);
    for (uint64_t i0 = 0; i0 < d.num_images(); i0 += k) {
      const uint64_t n = std::min(k, d.num_images() - i0);
      BTFC_RETURN_IF_ERROR(read_images(plan, i0, i0 + n, buf.data()));
      BTFC_RETURN_IF_ERROR(w.write_images(i0, n, buf.data()));
      if (progress) progress->advance();
    }
    if (progress) progress->finish();
    return {};
  }
  if (!in.model()) {  // raw data: a .btfc whose tensor is read in texel bands
    BTFC_ASSIGN_OR_RETURN(RawBands rb, RawBands::open(input));
    // Two float bands (the next one is read on a helper thread while this one is converted and
    // written) and the half copy of one band: 10 B/value.
    const uint64_t lines = band_lines(d, 10, max_bytes);
    std::vector<float> buf[2];
    buf[0].resize(lines * width * d.abrdf_size());
    buf[1].resize(buf[0].size());
    const uint64_t bands = (uint64_t(d.height) + lines - 1) / lines;
    auto count = [&](uint64_t b) { return std::min(lines, uint64_t(d.height) - b * lines) * width; };
    auto read = [&](uint64_t b) { return std::async(std::launch::async, [&, b] { return rb.read(b * lines * width, count(b), buf[b % 2].data()); }); };
    if (progress) progress->start("working file (raw texel bands)", bands);
    std::future<Status> next = read(0);
    for (uint64_t b = 0; b < bands; ++b) {
      Status s = next.get();
      if (s.ok() && b + 1 < bands) next = read(b + 1);
      if (s.ok()) s = w.write_texels(b * lines * width, count(b), buf[b % 2].data());
      if (!s.ok()) {
        if (next.valid()) (void)next.get();
        return s;
      }
      if (progress) progress->advance();
    }
    if (progress) progress->finish();
    return {};
  }
  const Model* model = in.model();  // a model input (model .btfc, Bonn file): decoded band by band
  const uint64_t lines = band_lines(d, 6, max_bytes);
  Btf band;
  if (progress) progress->start("working file (decoded texel bands)", (uint64_t(d.height) + lines - 1) / lines);
  for (uint64_t y = 0; y < uint64_t(d.height); y += lines) {
    DecodeRequest req;
    req.y0 = int(y);
    req.height = int(std::min(lines, uint64_t(d.height) - y));
    BTFC_RETURN_IF_ERROR(model->decode(req, band).with_context(input));
    BTFC_RETURN_IF_ERROR(band.check_finite(input));
    BTFC_RETURN_IF_ERROR(w.write_texels(y * width, uint64_t(req.height) * width, band.data()));
    if (progress) progress->advance();
  }
  if (progress) progress->finish();
  return {};
}

}  // namespace

Result<BtfDesc> probe_btf(const std::string& path) {
  BTFC_ASSIGN_OR_RETURN(std::unique_ptr<BtfInput> in, open_input(path));
  return in->desc();
}

Result<WorkFile> prepare_work_file(BtfInput& in, const std::string& work_path, uint32_t lines, size_t max_bytes, Progress* progress) {
  const std::string& input = in.path();
  const auto t0 = std::chrono::steady_clock::now();
  WorkFile wf;
  std::error_code ec;
  // An uncompressed BDI input is already a working file when its chunks fit the buffers.
  if (std::strcmp(in.format(), "bonn") == 0) {
    auto direct = BdiChunks::open(input);
    if (direct.ok() && direct->chunk_count(0) <= uint64_t(lines) * uint64_t(direct->desc().width)) {
      wf.path = input;
      wf.scale = direct->scale();
      return wf;
    }
  }
  const BtfDesc d = in.desc();
  const std::string fp = fingerprint(input);
  if (fs::exists(work_path, ec)) {
    auto old = BdiChunks::open(work_path);
    if (!old.ok()) {
      wf.note = old.status().message() + "; rebuilt";
    } else if (old->xml().find(fp) == std::string::npos) {
      wf.note = work_path + ": a working file of another source (or of a changed one); rebuilt";
    } else if (old->desc().abrdf_size() != d.abrdf_size() || old->desc().num_texels() != d.num_texels() ||
               old->chunk_count(0) > uint64_t(lines) * uint64_t(d.width)) {
      wf.note = work_path + ": a working file of another shape or chunking; rebuilt";
    } else {
      wf.path = work_path;
      wf.reused = true;
      wf.scale = old->scale();
      wf.note = work_path + ": complete working file of the same source reused";
      return wf;
    }
  }
  float scale = 1;
  for (int attempt = 0;; ++attempt) {
    char sbuf[32];
    std::snprintf(sbuf, sizeof sbuf, "%.9g", double(scale));
    const std::string xml = "<btfc_work scale=\"" + std::string(sbuf) + "\" " + fp + "/>";
    BTFC_ASSIGN_OR_RETURN(auto w, BdiWriter::create(work_path, d, lines, scale, xml));
    Status s = fill(in, *w, d, max_bytes, progress);
    if (s.ok()) {
      BTFC_RETURN_IF_ERROR(w->finish());
      break;
    }
    if (w->overflow() <= 0 || attempt >= 8) return s;
    // Headroom of 2^6 below the half maximum for values later in the input.
    const float want = w->overflow() * scale / 1024.0f;
    const float next = std::exp2(std::ceil(std::log2(std::isfinite(want) ? want : 1e30f)));
    wf.note += (wf.note.empty() ? "" : "; ") + std::string("values up to ") + std::to_string(w->overflow() * scale) +
               " exceed the half range: working file restarted with scale " + std::to_string(next);
    scale = std::max(next, scale * 2);
  }
  wf.path = work_path;
  wf.built = true;
  wf.scale = scale;
  wf.bytes_written = fs::file_size(work_path, ec);
  wf.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return wf;
}

Status decode_to_raw_btfc(const Model& model, const std::string& path, size_t max_bytes) {
  const BtfDesc& d = model.desc();
  // The decoded band and the writer's piece of the same band: 8 bytes per value.
  const uint64_t lines = band_lines(d, 8, max_bytes), width = uint64_t(d.width);
  Btf band;
  return save_raw_btf_streamed(d, path, lines * width, [&](uint64_t t0, uint64_t n, float* dst) -> Status {
    DecodeRequest req;  // pieces are whole bands: t0 and n are multiples of the width
    req.y0 = int(t0 / width);
    req.height = int(n / width);
    BTFC_RETURN_IF_ERROR(model.decode(req, band));
    std::memcpy(dst, band.data(), size_t(n * d.abrdf_size()) * sizeof(float));
    return {};
  });
}

Status decode_to_bdi(const Model& model, const std::string& path, size_t max_bytes) {
  const BtfDesc& d = model.desc();
  // The decoded band (float) plus its half copy: 6 bytes per value.
  const uint64_t lines = band_lines(d, 6, max_bytes);
  const std::string tmp = path + ".tmp-" + std::to_string(::getpid());
  {
    BTFC_ASSIGN_OR_RETURN(auto w, BdiWriter::create(tmp, d, uint32_t(std::min<uint64_t>(lines, 4)), 1.0f, "<btfc_decoded/>"));
    Btf band;
    for (uint64_t y = 0; y < uint64_t(d.height); y += lines) {
      DecodeRequest req;
      req.y0 = int(y);
      req.height = int(std::min(lines, uint64_t(d.height) - y));
      BTFC_RETURN_IF_ERROR(model.decode(req, band));
      Status s = w->write_texels(y * uint64_t(d.width), uint64_t(req.height) * uint64_t(d.width), band.data());
      if (!s.ok() && w->overflow() > 0)
        return unsupported(path + ": decoded values reach " + std::to_string(w->overflow()) +
                           ", beyond the half floats of a BDI file; decompress to .btfc instead");
      BTFC_RETURN_IF_ERROR(s);
    }
    BTFC_RETURN_IF_ERROR(w->finish());
  }
  std::error_code ec;
  fs::rename(tmp, path, ec);
  if (ec) {
    fs::remove(tmp, ec);
    return io_error(path + ": cannot rename the finished file into place");
  }
  return {};
}

}  // namespace btfc

namespace btfc {

Result<Metrics> compare_streamed(const BdiChunks& ref, const Model& model) {
  return compare_streamed(BdiChunkSource(ref), ref.desc(), ref.path(), model);
}

Result<Metrics> compare_streamed(const ChunkSource& ref, const BtfDesc& d, const std::string& path, const Model& model) {
  if (model.desc().abrdf_size() != d.abrdf_size() || model.desc().num_texels() != d.num_texels() || ref.rows() != d.abrdf_size() ||
      ref.texels() != d.num_texels())
    return invalid_argument(path + ": model shape differs from the reference BTF");
  if (ref.chunk_count(0) % uint64_t(d.width) != 0) return invalid_argument(path + ": reference chunks are not whole texel rows");
  double se = 0, sr = 0, mx = 0, peak = 0;
  std::vector<uint8_t> raw;
  std::vector<float> a;
  Btf band;
  for (uint64_t c = 0; c < ref.num_chunks(); ++c) {
    raw.resize(ref.raw_buffer_bytes(c));
    a.resize(ref.chunk_count(c) * ref.rows());
    BTFC_RETURN_IF_ERROR(ref.load(c, raw.empty() ? nullptr : raw.data(), a.data()));
    // Chunks are whole texel rows (BDI: formats.md 2.2; raw .btfc: open_raw_chunks).
    DecodeRequest req;
    req.y0 = int(ref.chunk_first(c) / uint64_t(d.width));
    req.height = int(ref.chunk_count(c) / uint64_t(d.width));
    BTFC_RETURN_IF_ERROR(model.decode(req, band));
    const float* b = band.data();
#pragma omp parallel for reduction(+ : se, sr) reduction(max : mx, peak) schedule(static)
    for (size_t i = 0; i < a.size(); ++i) {
      const double e = double(a[i]) - double(b[i]);
      se += e * e;
      sr += double(a[i]) * double(a[i]);
      mx = std::max(mx, std::fabs(e));
      peak = std::max(peak, double(a[i]));
    }
  }
  Metrics m;
  const double n = double(d.num_values());
  m.rmse = std::sqrt(se / n);
  m.rel_l2 = sr > 0 ? std::sqrt(se / sr) : (se > 0 ? INFINITY : 0);
  m.peak = (d.hdr || peak > 1) ? peak : 1.0;
  m.psnr = m.rmse > 0 ? 20 * std::log10(m.peak / m.rmse) : INFINITY;
  m.max_abs = mx;
  m.mean_ssim = NAN;
  return m;
}

}  // namespace btfc
