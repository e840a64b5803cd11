// mlvq model: chained-lookup decoding with 4D interpolation, evaluation at measured and arbitrary
// directions, storage (index streams plain or Huffman, scale codes, half level-1 values), loading
// with validation, GPU tensors. Layouts in mlvq_internal.h; stored tensors listed at save().
#include <Imath/half.h>

#include <algorithm>
#include <cmath>
#include <mutex>

#include "codecs/mlvq/mlvq_cl.h"
#include "codecs/mlvq/mlvq_internal.h"
#include "core/cl_runtime.h"
#include "core/quant.h"

namespace btfc::mlvq {

namespace {

const Book& book_of(const Hierarchy& h, Part p, int level) { return p == k_rgb ? h.rgb[level] : p == k_lum ? h.lum[level] : h.chroma[level]; }
const char* const k_part_names[3] = {"rgb", "lum", "chroma"};
std::string book_name(Part p, int k) { return std::string(k_part_names[p]) + std::to_string(k); }

}  // namespace

void decode_slice(const Hierarchy& h, int level, Part part, uint32_t idx, float sc, float* lum, float* chroma) {
  if (part == k_rgb && level == h.scheme) {
    decode_slice(h, level, k_lum, h.merge_lum[idx], sc, lum, nullptr);
    if (chroma) decode_slice(h, level, k_chroma, h.merge_chroma[idx], 1.f, nullptr, chroma);
    return;
  }
  const Book& b = book_of(h, part, level);
  if (level == 1) {
    const size_t nb = size_t(h.grid.nbeta);
    if (part == k_lum) {
      const float* v = &b.values[size_t(idx) * nb];
      for (size_t j = 0; j < nb; ++j) lum[j] = sc * v[j];
    } else {
      std::copy_n(&b.values[size_t(idx) * 2 * nb], 2 * nb, chroma);
    }
    return;
  }
  const size_t n = b.n, len = h.grid.slice_len(level - 1);
  for (size_t i = 0; i < n; ++i) {
    const size_t o = size_t(idx) * n + i;
    const float s2 = part == k_chroma ? 1.f : sc * b.scale[o];
    decode_slice(h, level - 1, part, b.child[o], s2, lum ? lum + i * len : nullptr, chroma ? chroma + 2 * i * len : nullptr);
  }
}

void decode_texel(const Hierarchy& h, size_t texel, float* lum, float* chroma) {
  decode_slice(h, 4, k_rgb, h.texel_idx[texel], h.texel_scale[texel], lum, chroma);
}

void node_lrg_many(const Hierarchy& h, size_t texel, const int (*coord)[5], size_t n, float (*lrg)[3]) {
  constexpr size_t G = 16;  // walks in flight: their loads of one level issue back to back
  for (size_t j0 = 0; j0 < n; j0 += G) {
    const size_t g = std::min(G, n - j0);
    const int (*cd)[5] = coord + j0;
    uint32_t e[G], li[G], ci[G];
    float sc[G];
    for (size_t j = 0; j < g; ++j) e[j] = h.texel_idx[texel], sc[j] = h.texel_scale[texel];
    const int s = h.scheme;
    for (int k = 4; k > s; --k) {
      const Book& b = h.rgb[k];
      for (size_t j = 0; j < g; ++j) {
        const size_t o = size_t(e[j]) * b.n + size_t(cd[j][k]);
        sc[j] *= b.scale[o];
        e[j] = b.child[o];
      }
    }
    for (size_t j = 0; j < g; ++j) li[j] = h.merge_lum[e[j]], ci[j] = h.merge_chroma[e[j]];
    for (int k = s; k > 1; --k)
      for (size_t j = 0; j < g; ++j) {
        const size_t o = size_t(li[j]) * h.lum[k].n + size_t(cd[j][k]);
        sc[j] *= h.lum[k].scale[o];
        li[j] = h.lum[k].child[o];
        ci[j] = h.chroma[k].child[size_t(ci[j]) * h.chroma[k].n + size_t(cd[j][k])];
      }
    const size_t nb = size_t(h.grid.nbeta);
    for (size_t j = 0; j < g; ++j) {
      float* out = lrg[j0 + j];
      out[0] = sc[j] * h.lum[1].values[size_t(li[j]) * nb + size_t(cd[j][1])];
      out[1] = h.chroma[1].values[2 * (size_t(ci[j]) * nb + size_t(cd[j][1]))];
      out[2] = h.chroma[1].values[2 * (size_t(ci[j]) * nb + size_t(cd[j][1])) + 1];
    }
  }
}

void node_lrg(const Hierarchy& h, size_t texel, const int coord[5], float lrg[3]) {
  node_lrg_many(h, texel, reinterpret_cast<const int(*)[5]>(coord), 1, reinterpret_cast<float(*)[3]>(lrg));
}

// Bit m of the result: node m of the stencil (level k's index (m >> k) & 1) has four nonzero level
// weights, the nodes eval_stencil sums.
static unsigned live_nodes(const Stencil& s) {
  constexpr unsigned k_half[4][2] = {{0x5555, 0xAAAA}, {0x3333, 0xCCCC}, {0x0F0F, 0xF0F0}, {0x00FF, 0xFF00}};
  unsigned live = 0xFFFF;
  for (int k = 0; k < 4; ++k) live &= (s.w[k][0] != 0 ? k_half[k][0] : 0u) | (s.w[k][1] != 0 ? k_half[k][1] : 0u);
  return live;
}

void eval_stencil(const Hierarchy& h, size_t texel, const Stencil& s, float rgb[3]) {
  float acc[3] = {0, 0, 0}, v[3], lrg[3];
  // Only the nodes whose four level weights are all nonzero, in the same ascending order: a
  // measured pair's stencil is one node, and computing the other 15 products only to skip them
  // was the largest part of a random query (perf, `btfc bench -c mlvq`). Same sums, same bits.
  for (unsigned live = live_nodes(s); live; live &= live - 1) {
    const int m = __builtin_ctz(live);
    const float w = s.w[0][m & 1] * s.w[1][(m >> 1) & 1] * s.w[2][(m >> 2) & 1] * s.w[3][(m >> 3) & 1];
    if (w == 0) continue;
    const int cd[5] = {0, s.i[0][m & 1], s.i[1][(m >> 1) & 1], s.i[2][(m >> 2) & 1], s.i[3][(m >> 3) & 1]};
    node_lrg(h, texel, cd, lrg);
    lrg_to_rgb(lrg, v);
    for (int c = 0; c < 3; ++c) acc[c] += w * v[c];
  }
  std::copy(acc, acc + 3, rgb);
}

// ---------------------------------------------------------------------------------------------

MlvqModel::MlvqModel(BtfDesc desc, std::string spec, Hierarchy h, bool huffman)
    : m_desc(std::move(desc)), m_spec(std::move(spec)), m_h(std::move(h)), m_huffman(huffman) {
  const size_t nl = m_desc.num_lights(), nv = m_desc.num_views();
  m_measured.resize(nl * nv);
  for (size_t v = 0; v < nv; ++v)
    for (size_t l = 0; l < nl; ++l) m_measured[l + nl * v] = measured_stencil(m_h.grid, m_desc, l, v);
  if (m_h.grid.measured()) m_li = DirectionInterpolator(m_desc.lights), m_vi = DirectionInterpolator(m_desc.views);
}

void MlvqModel::dir_pairs(const Vec3& wl, const Vec3& wv, uint32_t pair[9], float w[9]) const {
  const DirWeights a = m_li.weights(wl), b = m_vi.weights(wv);
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      pair[3 * i + j] = uint32_t(size_t(a.index[size_t(i)]) + m_desc.num_lights() * size_t(b.index[size_t(j)])),
                   w[3 * i + j] = a.weight[size_t(i)] * b.weight[size_t(j)];
}

// eval_stencil of each pair, with the codebook walks of all pairs' nodes interleaved
// (node_lrg_many): walked one after another, each walk's chain of dependent loads was most of a
// random query (perf, `btfc bench -c mlvq`). The same products and sums in the same order as
// eval_stencil per pair, so the same bits.
void MlvqModel::blend_measured(size_t texel, const Vec3& wl, const Vec3& wv, float rgb[3]) const {
  uint32_t pair[9];
  float w[9];
  dir_pairs(wl, wv, pair, w);
  int cd[9 * 16][5];
  float nw[9 * 16], lrg[9 * 16][3];
  int first[10];
  size_t n = 0;
  for (int k = 0; k < 9; ++k) {
    first[k] = int(n);
    if (w[k] == 0) continue;
    const Stencil& s = m_measured[pair[k]];
    for (unsigned live = live_nodes(s); live; live &= live - 1) {
      const int m = __builtin_ctz(live);
      const float wm = s.w[0][m & 1] * s.w[1][(m >> 1) & 1] * s.w[2][(m >> 2) & 1] * s.w[3][(m >> 3) & 1];
      if (wm == 0) continue;
      nw[n] = wm;
      cd[n][0] = 0, cd[n][1] = s.i[0][m & 1], cd[n][2] = s.i[1][(m >> 1) & 1], cd[n][3] = s.i[2][(m >> 2) & 1], cd[n][4] = s.i[3][(m >> 3) & 1];
      ++n;
    }
  }
  first[9] = int(n);
  node_lrg_many(m_h, texel, cd, n, lrg);
  rgb[0] = rgb[1] = rgb[2] = 0;
  for (int k = 0; k < 9; ++k) {
    if (w[k] == 0) continue;
    float acc[3] = {0, 0, 0}, v[3];
    for (int j = first[k]; j < first[k + 1]; ++j) {
      lrg_to_rgb(lrg[j], v);
      for (int c = 0; c < 3; ++c) acc[c] += nw[j] * v[c];
    }
    for (int c = 0; c < 3; ++c) rgb[c] += w[k] * acc[c];
  }
}

void MlvqModel::eval(int x, int y, int light, int view, float* out) const {
  float rgb[3];
  eval_stencil(m_h, size_t(x) + size_t(m_desc.width) * size_t(y), m_measured[size_t(light) + m_desc.num_lights() * size_t(view)], rgb);
  for (int c = 0; c < m_desc.channels; ++c) out[c] = rgb[c];
}

Status MlvqModel::eval_dir(int x, int y, const Vec3& wl, const Vec3& wv, float* out) const {
  if (x < 0 || y < 0 || x >= m_desc.width || y >= m_desc.height)
    return invalid_argument("texel (" + std::to_string(x) + ", " + std::to_string(y) + ") outside the BTF");
  float rgb[3];
  const size_t t = size_t(x) + size_t(m_desc.width) * size_t(y);
  if (m_h.grid.measured()) {
    blend_measured(t, wl, wv, rgb);
  } else {
    eval_stencil(m_h, t, stencil(m_h.grid, grid_coord(m_h.grid, wl, wv)), rgb);
  }
  for (int c = 0; c < m_desc.channels; ++c) out[c] = rgb[c];
  return {};
}

Status MlvqModel::eval_batch(std::span<const EvalQuery> q, float* out) const {
  const BtfDesc& d = m_desc;
  const size_t nc = size_t(d.channels);
  BTFC_RETURN_IF_ERROR(check_eval_queries(d, q));
  if (m_h.grid.measured()) {
    // Queries at arbitrary directions blend the 9 measured pairs around them (single grid nodes,
    // one codebook walk each), each query on its own, in parallel: expanding them into a batch
    // of 9 measured queries first (a fresh allocation of 9 EvalQuery per query, then OpenCL) ran
    // at 0.6-0.9 M evals/s on 2 cores, this at 2.6-3.2 (docs/benchmarks.md). The same sums as eval_dir.
    bool any = false;
    for (const EvalQuery& e : q) any = any || e.light < 0;
    if (any) {
      const size_t nl = d.num_lights();
#pragma omp parallel for schedule(static)
      for (long long i = 0; i < (long long)q.size(); ++i) {
        const EvalQuery& e = q[size_t(i)];
        const size_t t = size_t(e.x) + size_t(d.width) * size_t(e.y);
        float rgb[3];
        if (e.light >= 0) eval_stencil(m_h, t, m_measured[size_t(e.light) + nl * size_t(e.view)], rgb);
        else blend_measured(t, e.wl, e.wv, rgb);
        for (size_t c = 0; c < nc; ++c) out[size_t(i) * nc + c] = rgb[c];
      }
      return {};
    }
  }
  if (ocl::use_opencl()) {
    std::shared_ptr<DeviceModel> dev;
    Status st;
    {
      std::lock_guard<std::mutex> lock(m_dev_mu);
      if (!m_dev) {
        auto up = DeviceModel::upload(flatten(m_h));
        if (up.ok()) m_dev = up.value();
        else st = up.status();
      }
      dev = m_dev;
    }
    if (dev) {
      std::vector<int> texel(q.size());
      std::vector<float> coord(4 * q.size()), rgb(3 * q.size());
#pragma omp parallel for schedule(static)
      for (size_t i = 0; i < q.size(); ++i) {
        texel[i] = q[i].x + d.width * q[i].y;
        if (m_h.grid.measured()) {  // node coordinates of the measured pair (all queries are measured here)
          const size_t l = size_t(q[i].light), v = size_t(q[i].view), nb = size_t(m_h.grid.nbeta), nt = size_t(m_h.grid.ntheta);
          coord[4 * i] = float(v / nt), coord[4 * i + 1] = float(v % nt), coord[4 * i + 2] = float(l / nb), coord[4 * i + 3] = float(l % nb);
          continue;
        }
        const GridCoord c = q[i].light >= 0 ? grid_coord(m_h.grid, d.lights.dirs[size_t(q[i].light)], d.views.dirs[size_t(q[i].view)])
                                            : grid_coord(m_h.grid, q[i].wl, q[i].wv);
        coord[4 * i] = c.phi, coord[4 * i + 1] = c.theta, coord[4 * i + 2] = c.alpha, coord[4 * i + 3] = c.beta;
      }
      st = dev->eval(texel, coord, rgb.data());
      if (st.ok()) {
        for (size_t i = 0; i < q.size(); ++i)
          for (size_t c = 0; c < nc; ++c) out[i * nc + c] = rgb[3 * i + c];
        return {};
      }
    }
    if (!ocl::fall_back_after(st)) return st;
  }
#pragma omp parallel for schedule(static)
  for (size_t i = 0; i < q.size(); ++i) {
    const size_t t = size_t(q[i].x) + size_t(d.width) * size_t(q[i].y);
    const Stencil s = q[i].light >= 0 ? m_measured[size_t(q[i].light) + d.num_lights() * size_t(q[i].view)]
                                      : stencil(m_h.grid, grid_coord(m_h.grid, q[i].wl, q[i].wv));
    float rgb[3];
    eval_stencil(m_h, t, s, rgb);
    for (size_t c = 0; c < nc; ++c) out[i * nc + c] = rgb[c];
  }
  return {};
}

// The batched decode. Every texel is (4D entry, scale) and a scale multiplies R, G and B alike
// (chromaticity is scale-free), so the requested directions are evaluated once per *entry*:
// its whole grid by one recursive walk of the codebook chain (each slice visited once),
// converted to RGB, blended at the 16 nodes of every requested (light, view); then each texel
// of the entry is its scale times that row. The per-texel cost is one scaled copy of the row,
// so large BTFs (many texels per entry) decode at memory speed.
Status MlvqModel::decode(const DecodeRequest& req, Btf& out) const {
  BTFC_ASSIGN_OR_RETURN(ResolvedRequest rr, resolve_request(m_desc, req));
  BTFC_RETURN_IF_ERROR(prepare_output(rr.desc, out));
  const Grid& g = m_h.grid;
  const size_t G = g.size(), nl = rr.lights.size(), nv = rr.views.size(), nc = size_t(m_desc.channels);
  struct Tap {
    uint32_t node[16];
    float w[16];
  };
  std::vector<Tap> taps(nl * nv);
  for (size_t v = 0; v < nv; ++v)
    for (size_t l = 0; l < nl; ++l) {
      const Stencil& s = m_measured[size_t(rr.lights[l]) + m_desc.num_lights() * size_t(rr.views[v])];
      Tap& t = taps[l + nl * v];
      for (int m = 0; m < 16; ++m) {
        t.w[m] = s.w[0][m & 1] * s.w[1][(m >> 1) & 1] * s.w[2][(m >> 2) & 1] * s.w[3][(m >> 3) & 1];
        t.node[m] = uint32_t(size_t(s.i[0][m & 1]) +
                             size_t(g.nbeta) * (size_t(s.i[1][(m >> 1) & 1]) + size_t(g.nalpha) * (size_t(s.i[2][(m >> 2) & 1]) + size_t(g.ntheta) * size_t(s.i[3][(m >> 3) & 1])))) *
                    3;
      }
    }
  // Texels of the region grouped by their 4D entry (counting sort).
  const size_t w = size_t(rr.desc.width), n = rr.desc.num_texels(), rows = nl * nv * nc;
  const uint32_t K4 = m_h.scheme == 4 ? m_h.merge_size() : m_h.rgb[4].K;
  std::vector<uint32_t> start(size_t(K4) + 1, 0), order(n);
  auto texel_of = [&](size_t i) { return (size_t(rr.x0) + i % w) + size_t(m_desc.width) * (size_t(rr.y0) + i / w); };
  for (size_t i = 0; i < n; ++i) start[m_h.texel_idx[texel_of(i)] + 1]++;
  for (size_t k = 0; k < K4; ++k) start[k + 1] += start[k];
  {
    std::vector<uint32_t> pos(start.begin(), start.end() - 1);
    for (size_t i = 0; i < n; ++i) order[pos[m_h.texel_idx[texel_of(i)]]++] = uint32_t(i);
  }
#pragma omp parallel
  {
    std::vector<float> lum(G), chroma(2 * G), rgb(3 * G), row(rows);
#pragma omp for schedule(dynamic, 1)
    for (size_t e = 0; e < K4; ++e) {
      if (start[e] == start[e + 1]) continue;
      decode_slice(m_h, 4, k_rgb, uint32_t(e), 1.f, lum.data(), chroma.data());
      for (size_t j = 0; j < G; ++j) {
        const float lrg[3] = {lum[j], chroma[2 * j], chroma[2 * j + 1]};
        lrg_to_rgb(lrg, &rgb[3 * j]);
      }
      for (size_t r = 0; r < nl * nv; ++r) {
        const Tap& tp = taps[r];
        float a0 = 0, a1 = 0, a2 = 0;
        for (int m = 0; m < 16; ++m) {
          const float* p = &rgb[tp.node[m]];
          a0 += tp.w[m] * p[0], a1 += tp.w[m] * p[1], a2 += tp.w[m] * p[2];
        }
        const float v[3] = {a0, a1, a2};
        for (size_t c = 0; c < nc; ++c) row[r * nc + c] = v[c];
      }
      for (uint32_t k = start[e]; k < start[e + 1]; ++k) {
        const size_t i = order[k];
        const float sc = m_h.texel_scale[texel_of(i)];
        float* dst = out.data() + i * rows;
        for (size_t r = 0; r < rows; ++r) dst[r] = sc * row[r];
      }
    }
  }
  return {};
}

// ---- storage -------------------------------------------------------------------------------------
// Tensors: "mlvq" u32 [8] = scheme, nphi, ntheta, nalpha, nbeta, scale_bits, |M|, 0;
// "books" u32 [3, 5] = K per part (rgb, lum, chroma) and level (column 0 unused);
// "<part><k>.idx" u8 coded child indices (levels >= 2), "<part><k>.scale" u8/u16 codes and
// "<part><k>.range" f32 [2] (rgb and lum), "lum1.values" f16 [K, nbeta], "chroma1.values" f16
// [K, nbeta, 2], "merge.lum" / "merge.chroma" u8 coded, "texel.idx" u8 coded, "texel.scale",
// "texel.range".

namespace {

Tensor bytes_tensor(const std::string& name, std::vector<uint8_t> b) {
  Tensor t;
  t.name = name;
  t.dtype = DType::u8;
  t.shape = {uint64_t(b.size())};
  t.bytes = std::move(b);
  return t;
}

Tensor codes_tensor(const std::string& name, const std::vector<uint16_t>& c, int bits) {
  Tensor t;
  t.name = name;
  t.dtype = bits <= 8 ? DType::u8 : DType::u16;
  t.shape = {uint64_t(c.size())};
  for (uint16_t x : c) {
    t.bytes.push_back(uint8_t(x & 0xff));
    if (bits > 8) t.bytes.push_back(uint8_t(x >> 8));
  }
  return t;
}

Tensor half_tensor(const std::string& name, std::vector<uint64_t> shape, const std::vector<float>& v) {
  Tensor t;
  t.name = name;
  t.dtype = DType::f16;
  t.shape = std::move(shape);
  for (float x : v) {
    const uint16_t b = Imath::half(x).bits();
    t.bytes.push_back(uint8_t(b & 0xff)), t.bytes.push_back(uint8_t(b >> 8));
  }
  return t;
}

// Scale codes as a zq tensor of step 1 (the integers themselves, zstd-coded) when that is
// smaller than the plain u8 / u16 codes: on noisy HDR data the 16-bit codes are near-random in
// their low byte, elsewhere (LDR, repeated scales) zstd gains.
Tensor scale_tensor(const std::string& name, const std::vector<uint16_t>& c, int bits) {
  Tensor plain = codes_tensor(name, c, bits);
  if (c.empty()) return plain;
  std::vector<float> f(c.begin(), c.end());
  auto z = quant::encode(name, {uint64_t(c.size()), 1}, f.data(), {1.f}, {}, 19);
  return z.ok() && z.value().bytes.size() < plain.bytes.size() ? std::move(z).value() : plain;
}

Result<Tensor> value_tensor(const std::string& name, std::vector<uint64_t> shape, const std::vector<float>& v, int value_bits) {
  if (value_bits <= 0) return half_tensor(name, std::move(shape), v);
  const uint64_t cols = shape.back();
  return quant::encode(name, std::move(shape), v.data(), std::vector<float>(cols, std::ldexp(1.f, -value_bits)), {}, 19);
}

uint32_t child_alphabet(const Hierarchy& h, Part p, int level) {  // size of the book level-1 points into
  if (p == k_rgb && level - 1 == h.scheme) return h.merge_size();
  return book_of(h, p, level - 1).K;
}

}  // namespace

std::vector<Tensor> MlvqModel::tensors(bool allow_huffman, uint64_t* plain_bytes) const {
  const Hierarchy& h = m_h;
  std::vector<Tensor> ts;
  uint64_t plain = 0;
  auto coded = [&](const std::string& name, const std::vector<uint32_t>& v, uint32_t alphabet) {
    CodedStream cs = encode_indices(v, alphabet, allow_huffman);
    plain += cs.plain_bytes;
    ts.push_back(bytes_tensor(name, std::move(cs.bytes)));
  };
  auto other = [&](Tensor t) {
    plain += t.bytes.size();
    ts.push_back(std::move(t));
  };
  const uint32_t hdr[8] = {uint32_t(h.scheme), uint32_t(h.grid.nphi), uint32_t(h.grid.ntheta), uint32_t(h.grid.nalpha),
                           uint32_t(h.grid.nbeta), uint32_t(h.scale_bits), h.merge_size(), uint32_t(h.grid.layout)};
  other(Tensor::from_u32("mlvq", {8}, hdr));
  uint32_t books[15] = {0};
  for (int p = 0; p < 3; ++p)
    for (int k = 1; k <= 4; ++k) books[5 * p + k] = book_of(h, Part(p), k).K;
  other(Tensor::from_u32("books", {3, 5}, books));
  for (int p = 0; p < 3; ++p)
    for (int k = 2; k <= 4; ++k) {
      const Book& b = book_of(h, Part(p), k);
      if (b.K == 0) continue;
      coded(book_name(Part(p), k) + ".idx", b.child, child_alphabet(h, Part(p), k));
      if (p != k_chroma) {
        other(scale_tensor(book_name(Part(p), k) + ".scale", b.scode, h.scale_bits));
        const float r[2] = {b.lo, b.hi};
        other(Tensor::from_f32(book_name(Part(p), k) + ".range", {2}, r));
      }
    }
  // Values: f16 or zq; the encoder stored them quantized (store_value), so zq reproduces them
  // exactly and cannot fail on them (finite, |q| <= 2^value_bits).
  other(value_tensor("lum1.values", {h.lum[1].K, uint64_t(h.grid.nbeta)}, h.lum[1].values, h.value_bits).value());
  other(value_tensor("chroma1.values", {h.chroma[1].K, uint64_t(h.grid.nbeta), 2}, h.chroma[1].values, h.value_bits).value());
  coded("merge.lum", h.merge_lum, h.lum[h.scheme].K);
  coded("merge.chroma", h.merge_chroma, h.chroma[h.scheme].K);
  coded("texel.idx", h.texel_idx, h.scheme == 4 ? h.merge_size() : h.rgb[4].K);
  other(scale_tensor("texel.scale", h.texel_scode, h.scale_bits));
  const float r[2] = {h.texel_lo, h.texel_hi};
  other(Tensor::from_f32("texel.range", {2}, r));
  if (plain_bytes) *plain_bytes = plain;
  return ts;
}

Status MlvqModel::save(ContainerWriter& w) const {
  for (Tensor& t : tensors(m_huffman, nullptr)) w.add_tensor(std::move(t));
  return {};
}

uint64_t MlvqModel::payload_bytes() const {
  uint64_t n = 0;
  for (const Tensor& t : tensors(m_huffman, nullptr)) n += t.bytes.size();
  return n;
}

std::vector<std::pair<std::string, uint64_t>> MlvqModel::tensor_bytes() const {
  std::vector<std::pair<std::string, uint64_t>> v;
  for (const Tensor& t : tensors(m_huffman, nullptr)) v.emplace_back(t.name, t.bytes.size());
  return v;
}

uint64_t MlvqModel::plain_payload_bytes() const {
  uint64_t plain = 0;
  (void)tensors(false, &plain);
  return plain;
}

Result<std::vector<Tensor>> MlvqModel::gpu_tensors() const {
  const Hierarchy& h = m_h;
  std::vector<Tensor> out;
  const uint32_t grid[6] = {uint32_t(h.scheme), uint32_t(h.grid.nphi), uint32_t(h.grid.ntheta), uint32_t(h.grid.nalpha), uint32_t(h.grid.nbeta),
                            uint32_t(h.grid.layout)};
  out.push_back(Tensor::from_u32("grid", {6}, grid));
  out.push_back(Tensor::from_u32("texel_index", {uint64_t(m_desc.height), uint64_t(m_desc.width)}, h.texel_idx.data()));
  out.push_back(Tensor::from_f32("texel_scale", {uint64_t(m_desc.height), uint64_t(m_desc.width)}, h.texel_scale.data()));
  for (int p = 0; p < 3; ++p)
    for (int k = 2; k <= 4; ++k) {
      const Book& b = book_of(h, Part(p), k);
      if (b.K == 0) continue;
      out.push_back(Tensor::from_u32(book_name(Part(p), k) + "_index", {b.K, b.n}, b.child.data()));
      if (p != k_chroma) out.push_back(Tensor::from_f32(book_name(Part(p), k) + "_scale", {b.K, b.n}, b.scale.data()));
    }
  std::vector<uint32_t> m;
  for (size_t i = 0; i < h.merge_lum.size(); ++i) m.push_back(h.merge_lum[i]), m.push_back(h.merge_chroma[i]);
  out.push_back(Tensor::from_u32("merge", {h.merge_size(), 2}, m.data()));
  out.push_back(Tensor::from_f32("lum1", {h.lum[1].K, uint64_t(h.grid.nbeta)}, h.lum[1].values.data()));
  out.push_back(Tensor::from_f32("chroma1", {h.chroma[1].K, uint64_t(h.grid.nbeta), 2}, h.chroma[1].values.data()));
  return out;
}

Result<std::unique_ptr<Model>> MlvqModel::load(const ContainerReader& rd, const Params& p) {
  const BtfDesc& d = rd.desc();
  auto bad = [&](const std::string& what) { return corrupt_data(rd.path() + ": mlvq " + what); };
  if (d.channels != 3 && d.channels != 1) return bad("model with " + std::to_string(d.channels) + " channels (needs 1 or 3)");
  BTFC_ASSIGN_OR_RETURN(Tensor ht, rd.read_checked("mlvq", DType::u32, {8}));
  uint32_t hdr[8];
  std::copy(ht.bytes.begin(), ht.bytes.end(), reinterpret_cast<uint8_t*>(hdr));
  Hierarchy h;
  h.scheme = int(hdr[0]);
  if (h.scheme < 1 || h.scheme > 4) return bad("scheme " + std::to_string(hdr[0]) + " outside 1..4");
  for (int i = 1; i <= 4; ++i)
    if (hdr[i] < 1 || hdr[i] > 64) return bad("grid axis " + std::to_string(i) + " has " + std::to_string(hdr[i]) + " nodes (1..64)");
  h.grid.nphi = int(hdr[1]), h.grid.ntheta = int(hdr[2]), h.grid.nalpha = int(hdr[3]), h.grid.nbeta = int(hdr[4]);
  if (hdr[5] != 8 && hdr[5] != 16 && ((hdr[5] != 10 && hdr[5] != 12) || rd.codec().payload_version < 2))
    return bad("scale bits " + std::to_string(hdr[5]) + " (8, 16, or 10 / 12 from payload version 2)");
  h.scale_bits = int(hdr[5]);
  const uint32_t M = hdr[6];
  // Word 7: 0 in version 1 (grid layout); the layout from version 2 on.
  if (rd.codec().payload_version >= 2 && hdr[7] > 1) return bad("layout " + std::to_string(hdr[7]) + " (0 grid, 1 measured)");
  if (rd.codec().payload_version >= 2 && hdr[7] == k_layout_measured) {
    const Grid mg = measured_grid(d);
    if (mg.nphi != h.grid.nphi || mg.ntheta != h.grid.ntheta || mg.nalpha != h.grid.nalpha || mg.nbeta != h.grid.nbeta)
      return bad("measured layout " + std::to_string(h.grid.nphi) + " x " + std::to_string(h.grid.ntheta) + " x " + std::to_string(h.grid.nalpha) +
                 " x " + std::to_string(h.grid.nbeta) + " does not fit " + std::to_string(d.num_views()) + " views x " +
                 std::to_string(d.num_lights()) + " lights");
    h.grid = mg;
  }
  BTFC_ASSIGN_OR_RETURN(Tensor bt, rd.read_checked("books", DType::u32, {3, 5}));
  uint32_t books[15];
  std::copy(bt.bytes.begin(), bt.bytes.end(), reinterpret_cast<uint8_t*>(books));
  constexpr uint32_t k_max_k = 1u << 28;
  for (int p = 0; p < 3; ++p)
    for (int k = 1; k <= 4; ++k) {
      const uint32_t K = books[5 * p + k];
      const bool want = p == k_rgb ? k > h.scheme : k <= h.scheme;
      if (want != (K > 0) || K > k_max_k)
        return bad("codebook " + book_name(Part(p), k) + " has " + std::to_string(K) + " entries (scheme " + std::to_string(h.scheme) + ")");
      Book& b = p == k_rgb ? h.rgb[k] : p == k_lum ? h.lum[k] : h.chroma[k];
      b.K = K;
      b.n = uint32_t(h.grid.n(k));
    }
  if (M == 0 || M > k_max_k || uint64_t(M) > uint64_t(h.lum[h.scheme].K) * h.chroma[h.scheme].K)
    return bad("merge codebook of " + std::to_string(M) + " entries");
  const uint64_t N = d.num_texels();
  auto read_idx = [&](const std::string& name, size_t count, uint32_t alphabet) -> Result<std::vector<uint32_t>> {
    BTFC_ASSIGN_OR_RETURN(Tensor t, rd.read_checked(name, DType::u8, {}));
    return decode_indices(t.bytes, count, alphabet, rd.path() + ": mlvq tensor '" + name + "'");
  };
  auto read_scales = [&](const std::string& name, size_t count, std::vector<uint16_t>& codes, std::vector<float>& v, float& lo,
                         float& hi) -> Status {
    // The arrays are sized only after the tensor's shape was checked against `count`: the count
    // comes from DESC (texels), and a file declaring 2^30 texels must not allocate for them.
    const TensorInfo* ti = rd.find(name + ".scale");
    if (ti && ti->dtype == DType::zq) {  // version 2: the codes zstd-coded (scale_tensor)
      BTFC_ASSIGN_OR_RETURN(std::vector<float> f, rd.read_floats(name + ".scale", {uint64_t(count), 1}));
      codes.resize(count);
      v.resize(count);
      const float top = float((1u << h.scale_bits) - 1);
      for (size_t i = 0; i < count; ++i) {
        if (!(f[i] >= 0 && f[i] <= top && f[i] == std::floor(f[i]))) return bad("tensor '" + name + ".scale' holds a code outside 0.." + std::to_string(int(top)));
        codes[i] = uint16_t(f[i]);
      }
    } else {
      BTFC_ASSIGN_OR_RETURN(Tensor t, rd.read_checked(name + ".scale", h.scale_bits == 8 ? DType::u8 : DType::u16, {uint64_t(count)}));
      codes.resize(count);
      v.resize(count);
      for (size_t i = 0; i < count; ++i) {
        codes[i] = h.scale_bits == 8 ? t.bytes[i] : uint16_t(t.bytes[2 * i] | (t.bytes[2 * i + 1] << 8));
        if (codes[i] >= (1u << h.scale_bits)) return bad("tensor '" + name + ".scale' holds a code above " + std::to_string((1u << h.scale_bits) - 1));
      }
    }
    BTFC_ASSIGN_OR_RETURN(Tensor r, rd.read_checked(name + ".range", DType::f32, {2}));
    BTFC_ASSIGN_OR_RETURN(std::vector<float> rv, r.to_f32());
    lo = rv[0], hi = rv[1];
    if (!std::isfinite(lo) || !std::isfinite(hi) || lo > hi || hi > 88.f || lo < -104.f) return bad("tensor '" + name + ".range' is not a valid log range");
    for (size_t i = 0; i < count; ++i) v[i] = dequantize_scale(codes[i], lo, hi, h.scale_bits);
    return {};
  };
  for (int p = 0; p < 3; ++p)
    for (int k = 2; k <= 4; ++k) {
      Book& b = p == k_rgb ? h.rgb[k] : p == k_lum ? h.lum[k] : h.chroma[k];
      if (b.K == 0) continue;
      const uint32_t alpha = (p == k_rgb && k - 1 == h.scheme) ? M : book_of(h, Part(p), k - 1).K;
      BTFC_ASSIGN_OR_RETURN(b.child, read_idx(book_name(Part(p), k) + ".idx", size_t(b.K) * b.n, alpha));
      if (p != k_chroma) BTFC_RETURN_IF_ERROR(read_scales(book_name(Part(p), k), size_t(b.K) * b.n, b.scode, b.scale, b.lo, b.hi));
    }
  const uint64_t nb = uint64_t(h.grid.nbeta);
  {
    // f16 (version 1 and value_bits 0) or zq; read_floats refuses other dtypes and bad shapes.
    const TensorInfo* ti = rd.find("lum1.values");
    if (rd.codec().payload_version < 2 && ti && ti->dtype != DType::f16) return bad("tensor 'lum1.values' is not f16 (payload version 1)");
    BTFC_ASSIGN_OR_RETURN(h.lum[1].values, rd.read_floats("lum1.values", {h.lum[1].K, nb}));
    BTFC_ASSIGN_OR_RETURN(h.chroma[1].values, rd.read_floats("chroma1.values", {h.chroma[1].K, nb, 2}));
    if (ti && ti->dtype == DType::zq) {
      BTFC_ASSIGN_OR_RETURN(Tensor t, rd.read("lum1.values"));
      BTFC_ASSIGN_OR_RETURN(quant::Decoded dq, quant::decode_ints(t, rd.path() + ": mlvq tensor 'lum1.values'"));
      const int e = dq.steps.empty() ? 0 : -std::ilogb(dq.steps[0]);
      if (dq.steps.empty() || e < 1 || e > 16 || dq.steps[0] != std::ldexp(1.f, -e)) return bad("tensor 'lum1.values' step is not 2^-1 .. 2^-16");
      h.value_bits = e;
    }
    for (float x : h.lum[1].values)
      if (!std::isfinite(x)) return bad("tensor 'lum1.values' holds non-finite values");
    for (float x : h.chroma[1].values)
      if (!std::isfinite(x)) return bad("tensor 'chroma1.values' holds non-finite values");
  }
  BTFC_ASSIGN_OR_RETURN(h.merge_lum, read_idx("merge.lum", M, h.lum[h.scheme].K));
  BTFC_ASSIGN_OR_RETURN(h.merge_chroma, read_idx("merge.chroma", M, h.chroma[h.scheme].K));
  BTFC_ASSIGN_OR_RETURN(h.texel_idx, read_idx("texel.idx", N, h.scheme == 4 ? M : h.rgb[4].K));
  BTFC_RETURN_IF_ERROR(read_scales("texel", N, h.texel_scode, h.texel_scale, h.texel_lo, h.texel_hi));
  const bool huffman = p.get("huffman") != "off";
  auto model = std::make_unique<MlvqModel>(d, p.canonical(), std::move(h), huffman);
  model->mutable_stats().add("scheme", model->hierarchy().scheme);
  return std::unique_ptr<Model>(std::move(model));
}

}  // namespace btfc::mlvq
