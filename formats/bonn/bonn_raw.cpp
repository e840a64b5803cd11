// Bonn PVF (!PVF06FC[R], per-view PCA) and BDI (!BDIF06R2!, raw ABRDF chunks) as read-only
// models (formats.md 2.2: BTFLIB read_ubo_pvf.m, decode_pvf_abrdf.m, read_ubo_bdi.m,
// write_ubo_bdi.m; layouts pinned in docs/FORMAT.md "Bonn .btf files").
#include <bzlib.h>

#include <Imath/half.h>
#include <atomic>
#include <cmath>
#include <cstring>
#include <mutex>

#include "core/interp.h"
#include "formats/bonn/bonn_io.h"

namespace btfc::bonn {
namespace {

// Shared by PVF and BDI: a model that produces one texel's full ABRDF (row = c + nC*(l + nL*v))
// and derives decode / eval_dir from it. Neither format is a btfc codec, so save() refuses.
class AbrdfModel : public Model {
 public:
  AbrdfModel(BtfDesc desc, std::string spec, uint64_t payload)
      : m_desc(std::move(desc)), m_spec(std::move(spec)), m_payload(payload), m_li(m_desc.lights), m_vi(m_desc.views) {}
  const BtfDesc& desc() const override { return m_desc; }
  const std::string& spec() const override { return m_spec; }
  uint64_t payload_bytes() const override { return m_payload; }
  ModelStats stats() const override { return m_stats; }
  ModelStats& mutable_stats() { return m_stats; }
  Status save(ContainerWriter&) const override {
    return unsupported(m_spec + ": a Bonn " + m_spec.substr(5) + " file cannot be stored as a .btfc model; decompress or re-compress it");
  }

  // Values of rows [r0, r0 + n) of texel t (x + width*y). Must be thread-safe.
  virtual Status rows(size_t t, size_t r0, size_t n, float* out) const = 0;
  virtual bool parallel_decode() const { return true; }

  void eval(int x, int y, int l, int v, float* out) const override {
    const size_t t = size_t(x) + size_t(m_desc.width) * size_t(y);
    if (!rows(t, m_desc.row(size_t(l), size_t(v), 0), size_t(m_desc.channels), out).ok())
      for (int c = 0; c < m_desc.channels; ++c) out[c] = std::nanf("");  // eval cannot report; NaN marks a read failure
  }

  Status eval_dir(int x, int y, const Vec3& wl, const Vec3& wv, float* out) const override {
    if (x < 0 || y < 0 || x >= m_desc.width || y >= m_desc.height)
      return invalid_argument("texel (" + std::to_string(x) + ", " + std::to_string(y) + ") outside the BTF");
    const DirWeights a = m_li.weights(wl), b = m_vi.weights(wv);
    float acc[64] = {0}, tmp[64];
    const size_t t = size_t(x) + size_t(m_desc.width) * size_t(y);
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) {
        const float w = a.weight[i] * b.weight[j];
        if (w == 0) continue;
        BTFC_RETURN_IF_ERROR(rows(t, m_desc.row(size_t(a.index[i]), size_t(b.index[j]), 0), size_t(m_desc.channels), tmp));
        for (int c = 0; c < m_desc.channels; ++c) acc[c] += w * tmp[c];
      }
    std::memcpy(out, acc, sizeof(float) * size_t(m_desc.channels));
    return {};
  }

  Status decode(const DecodeRequest& req, Btf& out) const override {
    BTFC_ASSIGN_OR_RETURN(ResolvedRequest rr, resolve_request(m_desc, req));
    BTFC_RETURN_IF_ERROR(prepare_output(rr.desc, out));
    const size_t n = rr.desc.num_texels(), w = size_t(rr.desc.width), nc = size_t(m_desc.channels);
    const size_t m = rr.desc.abrdf_size(), full = m_desc.abrdf_size();
    std::atomic<bool> failed{false};
    Status first_error;
    std::mutex mu;
#pragma omp parallel if (parallel_decode())
    {
      std::vector<float> abrdf(full);
#pragma omp for schedule(dynamic, 16)
      for (size_t i = 0; i < n; ++i) {
        if (failed.load(std::memory_order_relaxed)) continue;
        const size_t t = (size_t(rr.x0) + i % w) + size_t(m_desc.width) * (size_t(rr.y0) + i / w);
        Status s = rows(t, 0, full, abrdf.data());
        if (!s.ok()) {
          std::lock_guard<std::mutex> lock(mu);
          if (!failed.exchange(true)) first_error = s;
          continue;
        }
        float* dst = out.data() + i * m;
        for (size_t v = 0; v < rr.views.size(); ++v)
          for (size_t l = 0; l < rr.lights.size(); ++l)
            std::memcpy(dst + nc * (l + rr.lights.size() * v), abrdf.data() + m_desc.row(size_t(rr.lights[l]), size_t(rr.views[v]), 0),
                        nc * sizeof(float));
      }
    }
    return failed ? first_error : Status{};
  }

 protected:
  BtfDesc m_desc;
  std::string m_spec;
  uint64_t m_payload;
  DirectionInterpolator m_li, m_vi;
  ModelStats m_stats;
};

// ---- PVF ----

// Per view v: mean M [dim], components Cm [dim][k], weights W [nw][k] (row-major).
// Layout "light fields": dim = nC*nL, nw = texels: row c + nC*l of texel t = M + Cm[row] . W[t].
// Layout "images":       dim = nC*texels, nw = nL: (c, t) of light l  = M[c + nC*t] + Cm[c + nC*t] . W[l].
struct PvfView {
  std::vector<float> M, Cm, W;
  int k = 0;
  bool images = false;
};

class PvfModel final : public AbrdfModel {
 public:
  PvfModel(BtfDesc d, uint64_t payload, std::vector<PvfView> views)
      : AbrdfModel(std::move(d), "bonn-PVF", payload), m_views(std::move(views)) {}
  Status rows(size_t t, size_t r0, size_t n, float* out) const override {
    const size_t nc = size_t(m_desc.channels), nl = m_desc.num_lights();
    for (size_t i = 0; i < n; ++i) {
      const size_t r = r0 + i, c = r % nc, l = (r / nc) % nl, v = r / (nc * nl);
      const PvfView& pv = m_views[v];
      const size_t k = size_t(pv.k);
      const size_t mr = pv.images ? c + nc * t : c + nc * l, wr = pv.images ? l : t;
      const float* a = &pv.Cm[mr * k];
      const float* b = &pv.W[wr * k];
      float s = pv.M[mr];
      for (size_t j = 0; j < k; ++j) s += a[j] * b[j];
      out[i] = s;
    }
    return {};
  }

 private:
  std::vector<PvfView> m_views;
};

// ---- BDI ----

class BdiModel final : public AbrdfModel {
 public:
  BdiModel(BtfDesc d, uint64_t payload, ByteSource src, int compression, uint64_t per_chunk, std::vector<int64_t> storage,
           std::vector<uint64_t> chunk_off, std::vector<uint32_t> chunk_bytes, uint64_t stored)
      : AbrdfModel(std::move(d), "bonn-BDI", payload), m_src(std::move(src)), m_compression(compression), m_per_chunk(per_chunk),
        m_storage(std::move(storage)), m_off(std::move(chunk_off)), m_bytes(std::move(chunk_bytes)), m_stored(stored) {}

  // bzip2 chunks are decompressed whole; decode walks texels in chunk order, one thread.
  bool parallel_decode() const override { return m_compression != 1; }

  Status rows(size_t t, size_t r0, size_t n, float* out) const override {
    const int64_t s = m_storage[t];
    if (s < 0) {  // sparse BDI: a texel outside the mask is black
      std::fill(out, out + n, 0.0f);
      return {};
    }
    const uint64_t chunk = uint64_t(s) / m_per_chunk, within = uint64_t(s) % m_per_chunk;
    const uint64_t first = (within * m_desc.abrdf_size() + r0) * 2;
    std::vector<uint16_t> h(n);
    if (m_compression != 1) {
      BTFC_RETURN_IF_ERROR(m_src.read_at(m_off[chunk] + first, h.data(), n * 2, "BDI chunk " + std::to_string(chunk)));
    } else {
      BTFC_ASSIGN_OR_RETURN(auto data, chunk_data(chunk));
      std::memcpy(h.data(), data->data() + first / 2, n * 2);
    }
    for (size_t i = 0; i < n; ++i) {
      Imath::half v;
      v.setBits(h[i]);
      out[i] = float(v);
    }
    return {};
  }

 private:
  uint64_t chunk_texels(uint64_t chunk) const { return std::min(m_per_chunk, m_stored - chunk * m_per_chunk); }

  Result<std::shared_ptr<const std::vector<uint16_t>>> chunk_data(uint64_t chunk) const {
    std::lock_guard<std::mutex> lock(m_mu);
    if (m_cached && m_cached_index == chunk) return m_cached;
    const std::string f = "BDI chunk " + std::to_string(chunk);
    std::vector<char> comp(m_bytes[chunk]);
    BTFC_RETURN_IF_ERROR(m_src.read_at(m_off[chunk], comp.data(), comp.size(), f));
    const uint64_t want = chunk_texels(chunk) * m_desc.abrdf_size() * 2;
    // A bzip2 chunk declares its decompressed size (a few bytes can inflate to GBs): refuse one
    // over the memory limit before allocating (core/limits.h).
    BTFC_RETURN_IF_ERROR(check_memory(size_t(want), m_src.path() + ": " + f + " decompressed"));
    auto out = std::make_shared<std::vector<uint16_t>>(want / 2 + 1);
    unsigned int got = unsigned(want + 2);  // one spare value: a longer stream is detected, not truncated
    const int rc = BZ2_bzBuffToBuffDecompress(reinterpret_cast<char*>(out->data()), &got, comp.data(), unsigned(comp.size()), 0, 0);
    if (rc == BZ_OUTBUFF_FULL || (rc == BZ_OK && got != want))
      return m_src.corrupt(f + " decompresses to " + (rc == BZ_OK ? std::to_string(got) : "more than " + std::to_string(want)) +
                           " bytes, expected " + std::to_string(want));
    if (rc != BZ_OK) return m_src.corrupt(f + " is not a valid bzip2 stream (libbz2 error " + std::to_string(rc) + ")");
    m_cached = out;
    m_cached_index = chunk;
    return m_cached;
  }

  ByteSource m_src;
  int m_compression;
  uint64_t m_per_chunk;
  std::vector<int64_t> m_storage;  // per texel: index among stored texels, -1 = not stored
  std::vector<uint64_t> m_off;     // chunk payload offsets
  std::vector<uint32_t> m_bytes;   // chunk payload sizes
  uint64_t m_stored;
  mutable std::mutex m_mu;
  mutable std::shared_ptr<const std::vector<uint16_t>> m_cached;
  mutable uint64_t m_cached_index = 0;
};

}  // namespace

Result<std::unique_ptr<Model>> read_pvf(ByteSource& src, BonnInfo& info, bool load) {
  uint32_t ncomp = 0, nviews = 0;
  BTFC_RETURN_IF_ERROR(src.u32(ncomp, "PVF num_components"));
  BTFC_RETURN_IF_ERROR(src.u32(nviews, "PVF num_view_slots"));
  const BtfDesc& d = info.desc;
  if (nviews != d.num_views())
    return src.corrupt("PVF num_view_slots " + std::to_string(nviews) + " disagrees with the sampling's " + std::to_string(d.num_views()) + " views");
  const uint64_t nc = uint64_t(d.channels), texels = d.num_texels(), nl = d.num_lights();
  std::vector<PvfView> views;
  for (uint32_t v = 0; v < nviews; ++v) {
    const std::string f = "PVF view " + std::to_string(v);
    uint8_t ss = 0;
    uint32_t k = 0, nw = 0, dim = 0;
    BTFC_RETURN_IF_ERROR(src.u8(ss, f + " scalar_size"));
    if (ss != 2 && ss != 4 && ss != 8) return src.corrupt(f + " scalar_size " + std::to_string(ss) + " (2, 4 or 8 expected)");
    BTFC_RETURN_IF_ERROR(src.u32(k, f + " num_components"));
    BTFC_RETURN_IF_ERROR(src.u32(nw, f + " num_weights"));
    BTFC_RETURN_IF_ERROR(src.u32(dim, f + " dimension"));
    if (k == 0) return src.corrupt(f + " num_components is 0");
    // k + dim + dim*k + nw*k scalars, overflow-checked, against the file before allocating.
    uint64_t ck, wk, total, bytes;
    if (!mul_ok(dim, k, ck) || !mul_ok(nw, k, wk) || __builtin_add_overflow(ck, wk, &total) ||
        __builtin_add_overflow(total, uint64_t(k) + dim, &total) || !mul_ok(total, ss, bytes) || bytes > src.remaining())
      return src.corrupt(f + " data (num_components " + std::to_string(k) + ", num_weights " + std::to_string(nw) + ", dimension " +
                         std::to_string(dim) + ") exceeds the file (" + std::to_string(src.remaining()) + " bytes left)");
    PvfView pv;
    pv.k = int(k);
    if (dim == nc * nl && nw == texels) pv.images = false;
    else if (dim == nc * texels && nw == nl) pv.images = true;
    else
      return src.corrupt(f + " dimension " + std::to_string(dim) + " / num_weights " + std::to_string(nw) +
                         " match neither layout (channels x lights / texels, or channels x texels / lights)");
    info.scalar_sizes.push_back(ss);
    info.components.push_back(int(k));
    if (!load) {
      BTFC_RETURN_IF_ERROR(src.skip(bytes, f + " data"));
      continue;
    }
    std::vector<float> evs(k);
    pv.M.resize(dim);
    pv.Cm.resize(size_t(ck));
    pv.W.resize(size_t(wk));
    BTFC_RETURN_IF_ERROR(src.scalars(evs.data(), k, ss, f + " EVs"));  // eigenvalues: informational
    BTFC_RETURN_IF_ERROR(src.scalars(pv.M.data(), dim, ss, f + " mean"));
    BTFC_RETURN_IF_ERROR(src.scalars(pv.Cm.data(), ck, ss, f + " C"));
    BTFC_RETURN_IF_ERROR(src.scalars(pv.W.data(), wk, ss, f + " W"));
    views.push_back(std::move(pv));
  }
  (void)ncomp;  // the file-wide maximum; each view carries its own count
  if (!load) return std::unique_ptr<Model>();
  auto m = std::make_unique<PvfModel>(info.desc, src.size(), std::move(views));
  return std::unique_ptr<Model>(std::move(m));
}

Result<std::unique_ptr<Model>> read_bdi(ByteSource& src, BonnInfo& info, bool load) {
  // After the sampling: width, height, scan_lines_per_chunk, compression, mask, rotations.
  BTFC_RETURN_IF_ERROR(read_size(src, info));
  BTFC_RETURN_IF_ERROR(src.u32(info.bdi_scan_lines_per_chunk, "BDI scan_lines_per_chunk"));
  uint8_t comp = 0;
  BTFC_RETURN_IF_ERROR(src.u8(comp, "BDI compression"));
  if (comp > 2) return src.corrupt("BDI compression " + std::to_string(comp) + " (0 full, 1 bzip2, 2 sparse expected)");
  info.bdi_compression = comp;
  if (info.bdi_scan_lines_per_chunk == 0) return src.corrupt("BDI scan_lines_per_chunk is 0");
  BTFC_RETURN_IF_ERROR(finish_desc(src, info));
  const BtfDesc& d = info.desc;
  const uint64_t texels = d.num_texels();
  BTFC_RETURN_IF_ERROR(src.need(texels, "BDI mask (" + std::to_string(d.width) + " x " + std::to_string(d.height) + ")"));
  std::vector<uint8_t> mask(texels);
  BTFC_RETURN_IF_ERROR(src.bytes(mask.data(), texels, "BDI mask"));
  BTFC_RETURN_IF_ERROR(read_rotations(src, info));
  // Storage order: texels x fastest, then y (the writer's column-major mask(x, y)); a sparse
  // BDI stores only mask != 0 texels, in that order.
  std::vector<int64_t> storage(texels);
  uint64_t stored = 0;
  for (uint64_t t = 0; t < texels; ++t) storage[t] = (comp != 2 || mask[t]) ? int64_t(stored++) : -1;
  info.bdi_stored_texels = stored;
  const uint64_t per_chunk = uint64_t(d.width) * info.bdi_scan_lines_per_chunk;
  const uint64_t num_chunks = (stored + per_chunk - 1) / per_chunk;
  BTFC_RETURN_IF_ERROR(src.need(num_chunks * 4, "BDI chunk table (" + std::to_string(num_chunks) + " chunks)"));
  std::vector<uint64_t> off(num_chunks);
  std::vector<uint32_t> sizes(num_chunks);
  const uint64_t abrdf_bytes = d.abrdf_size() * 2;
  for (uint64_t c = 0; c < num_chunks; ++c) {
    const std::string f = "BDI chunk " + std::to_string(c);
    BTFC_RETURN_IF_ERROR(src.u32(sizes[c], f + " chunk_bytes"));
    const uint64_t want = std::min(per_chunk, stored - c * per_chunk) * abrdf_bytes;
    if (comp == 1 && want > 0xfffffffeull)  // libbz2's buffer API counts in unsigned int
      return unsupported(src.path() + ": " + f + " decompresses to " + std::to_string(want) + " bytes (at most 4 GiB supported)");
    if (comp != 1 && sizes[c] != want)
      return src.corrupt(f + " chunk_bytes " + std::to_string(sizes[c]) + " disagrees with " + std::to_string(want) +
                         " (texels x channels x lights x views x 2)");
    off[c] = src.pos();
    BTFC_RETURN_IF_ERROR(src.skip(sizes[c], f + " data (chunk_bytes " + std::to_string(sizes[c]) + ")"));
  }
  info.scalar_sizes.push_back(2);
  info.components.push_back(0);
  if (!load) return std::unique_ptr<Model>();
  auto m = std::make_unique<BdiModel>(info.desc, src.size(), src, comp, per_chunk, std::move(storage), std::move(off), std::move(sizes), stored);
  m->mutable_stats().add("bdi_stored_texels", double(stored));
  return std::unique_ptr<Model>(std::move(m));
}

}  // namespace btfc::bonn
