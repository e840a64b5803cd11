// mlvq GPU export: the codebook hierarchy as textures (layout in codecs/mlvq/mlvq_export.h) plus
// the manifest's "evaluation" object. The shader and its CPU emulation: mlvq_export_glsl.cpp.
#include "codecs/mlvq/mlvq_export.h"
#include "codecs/mlvq/mlvq.h"

#include <algorithm>
#include <cmath>

#include "codecs/mlvq/mlvq_internal.h"

namespace btfc::gpu {
namespace mlvq_export {

std::string book_texture(const char* part, int level, const char* what) {
  return std::string(part) + std::to_string(level) + "_" + what;
}

namespace {

using mlvq::Book;
using mlvq::Hierarchy;

constexpr const char* k_parts[3] = {"rgb", "lum", "chroma"};

// Half storage of scale factors: a power of two s with max|x| / s in [2^14, 2^15]. Chained scales
// multiply, so their streams span many octaves *downwards* (16-bit HDR scales: up to ~60);
// half_safe_scale only guards overflow, while this also moves the small scales out of the half
// subnormals (relative precision lost below 2^-14). Dividing by a power of two is exact.
double half_range_scale(const std::vector<float>& v) {
  float mx = 0;
  for (float x : v) mx = std::max(mx, std::fabs(x));
  if (!(mx > 0) || !std::isfinite(mx)) return 1;
  int e = 0;
  std::frexp(mx, &e);  // mx <= 2^e
  return std::ldexp(1.0, e - 15);
}

struct Builder {
  const ExportOptions& opt;
  ExportBundle& b;
  uint64_t subnormal = 0;  // nonzero scale factors stored as half subnormals (relative precision lost)

  // A 1D array of `count` entries x `ch` channels as a k_line_width-wide 2D texture.
  static void line_shape(size_t count, uint32_t& w, uint32_t& h) {
    w = uint32_t(std::min<size_t>(std::max<size_t>(count, 1), k_line_width));
    h = uint32_t((std::max<size_t>(count, 1) + w - 1) / w);
  }

  Status add_index(std::string name, std::vector<uint32_t> v, size_t count, int ch, uint64_t alphabet, bool line, uint32_t w,
                   uint32_t h, std::string meaning, std::vector<std::string> channels) {
    if (line) line_shape(count, w, h);
    TexFormat f;
    if (ch == 1) f = alphabet <= 65536 ? TexFormat::r16_uint : TexFormat::r32_uint;
    else f = alphabet <= 65536 ? TexFormat::rg16_uint : TexFormat::rgba32_uint;
    const int fc = format_info(f).channels;
    std::vector<uint32_t> data(size_t(w) * h * size_t(fc), 0);
    for (size_t i = 0; i < count; ++i)
      for (int c = 0; c < ch; ++c) data[i * size_t(fc) + size_t(c)] = v[i * size_t(ch) + size_t(c)];
    BTFC_ASSIGN_OR_RETURN(GpuTexture t, make_uint_texture(std::move(name), f, w, h, 0, std::move(data)));
    t.meaning = std::move(meaning);
    while (channels.size() < size_t(fc)) channels.push_back("unused");
    t.channel_meaning = std::move(channels);
    b.textures.push_back(std::move(t));
    return {};
  }

  // `rescale`: scale factors (half_range_scale under half storage); else values stored as they
  // are (level-1 vectors are already half-rounded by the encoder, so r16f holds them exactly).
  Status add_float(std::string name, std::vector<float> v, size_t count, int ch, bool rescale, bool line, uint32_t w, uint32_t h,
                   std::string meaning, std::vector<std::string> channels) {
    if (line) line_shape(count, w, h);
    const TexFormat f = ch == 1 ? (opt.half ? TexFormat::r16f : TexFormat::r32f) : (opt.half ? TexFormat::rg16f : TexFormat::rg32f);
    const double s = rescale && opt.half && !opt.clamp_half ? half_range_scale(v) : 1.0;
    std::vector<float> data(size_t(w) * h * size_t(ch), 0.f);
    for (size_t i = 0; i < count * size_t(ch); ++i) data[i] = float(v[i] / s);
    if (opt.half && rescale)
      for (size_t i = 0; i < count * size_t(ch); ++i)
        if (data[i] != 0 && std::fabs(data[i]) < 6.103515625e-05f) ++subnormal;
    BTFC_ASSIGN_OR_RETURN(GpuTexture t, make_float_texture(std::move(name), f, w, h, 0, std::move(data)));
    t.scale = s;
    t.meaning = std::move(meaning);
    t.channel_meaning = std::move(channels);
    b.textures.push_back(std::move(t));
    return {};
  }
};

uint32_t child_alphabet(const Hierarchy& h, int part, int level) {
  if (part == 0 && level - 1 == h.scheme) return h.merge_size();
  const Book& below = part == 0 ? h.rgb[level - 1] : part == 1 ? h.lum[level - 1] : h.chroma[level - 1];
  return below.K;
}

const char* const k_axis_names[5] = {"", "beta", "alpha", "theta", "phi"};

Result<ExportBundle> build(const Model& model, const ExportOptions& opt) {
  const auto* mm = dynamic_cast<const mlvq::MlvqModel*>(&model);
  if (!mm) return invalid_argument("export: model '" + model.spec() + "' is not an mlvq model");
  const Hierarchy& h = mm->hierarchy();
  const BtfDesc& d = model.desc();
  const mlvq::Grid& g = h.grid;
  ExportBundle b;
  b.desc = d, b.spec = model.spec();
  Builder B{opt, b};
  const uint32_t W = uint32_t(d.width), H = uint32_t(d.height), N = W * H;
  const uint32_t K4 = h.scheme == 4 ? h.merge_size() : h.rgb[4].K;
  BTFC_RETURN_IF_ERROR(B.add_index("texel_index", h.texel_idx, N, 1, K4, false, W, H,
                                   std::string("entry of the texel's 4D vector in ") + (h.scheme == 4 ? "merge" : "rgb4"), {"entry"}));
  BTFC_RETURN_IF_ERROR(B.add_float("texel_scale", h.texel_scale, N, 1, true, false, W, H,
                                   "scale factor of the texel's 4D vector (multiplies luminance); value = stored * scale", {"scale"}));
  nlohmann::json books = nlohmann::json::array();
  for (int k = 4; k >= 2; --k)
    for (int p = 0; p < 3; ++p) {
      const Book& bk = p == 0 ? h.rgb[k] : p == 1 ? h.lum[k] : h.chroma[k];
      if (bk.K == 0) continue;
      const size_t count = size_t(bk.K) * bk.n;
      const uint32_t alpha = child_alphabet(h, p, k);
      const std::string below = p == 0 && k - 1 == h.scheme ? "merge" : std::string(k_parts[p]) + std::to_string(k - 1);
      BTFC_RETURN_IF_ERROR(B.add_index(book_texture(k_parts[p], k, "index"), bk.child, count, 1, alpha, true, 0, 0,
                                       std::string(k_parts[p]) + std::to_string(k) + " entry e, " + k_axis_names[k] + " node c -> entry of " + below +
                                           " at [e * " + std::to_string(bk.n) + " + c]",
                                       {"child entry"}));
      nlohmann::json j = {{"part", k_parts[p]},      {"level", k},
                          {"axis", k_axis_names[k]}, {"entries", bk.K},
                          {"children", bk.n},        {"child_book", below},
                          {"child_alphabet", alpha}, {"index_texture", book_texture(k_parts[p], k, "index")}};
      if (p != 2) {
        BTFC_RETURN_IF_ERROR(B.add_float(book_texture(k_parts[p], k, "scale"), bk.scale, count, 1, true, true, 0, 0,
                                         std::string(k_parts[p]) + std::to_string(k) + " scale of child [e * " + std::to_string(bk.n) +
                                             " + c] (multiplies luminance); value = stored * scale",
                                         {"scale"}));
        j["scale_texture"] = book_texture(k_parts[p], k, "scale");
      }
      books.push_back(j);
    }
  std::vector<uint32_t> merge(2 * size_t(h.merge_size()));
  for (size_t i = 0; i < h.merge_size(); ++i) merge[2 * i] = h.merge_lum[i], merge[2 * i + 1] = h.merge_chroma[i];
  const uint64_t malpha = std::max(h.lum[h.scheme].K, h.chroma[h.scheme].K);
  const std::string ls = "lum" + std::to_string(h.scheme), cs = "chroma" + std::to_string(h.scheme);
  BTFC_RETURN_IF_ERROR(B.add_index("merge", merge, h.merge_size(), 2, malpha, true, 0, 0,
                                   "merge codebook M (luminance / chromaticity split at level " + std::to_string(h.scheme) + ")",
                                   {"entry of " + ls, "entry of " + cs}));
  BTFC_RETURN_IF_ERROR(B.add_float("lum1", h.lum[1].values, size_t(h.lum[1].K) * size_t(g.nbeta), 1, false, true, 0, 0,
                                   "level-1 luminance vectors: entry e, beta node c at [e * nbeta + c]", {"luminance"}));
  BTFC_RETURN_IF_ERROR(B.add_float("chroma1", h.chroma[1].values, size_t(h.chroma[1].K) * size_t(g.nbeta), 2, false, true, 0, 0,
                                   "level-1 chromaticity vectors: entry e, beta node c at [e * nbeta + c]", {"r = R / (R + G + B)", "g = G / (R + G + B)"}));
  {
    const size_t nl = d.num_lights(), nv = d.num_views();
    std::vector<float> mc(nl * nv * 4);
    for (size_t v = 0; v < nv; ++v)
      for (size_t l = 0; l < nl; ++l) {
        float* o = &mc[(v * nl + l) * 4];
        if (g.measured()) {  // the node of the pair: integer coordinates (weight 1 on one node)
          const mlvq::Stencil st = mlvq::measured_stencil(g, d, l, v);
          o[0] = float(st.i[3][0]), o[1] = float(st.i[2][0]), o[2] = float(st.i[1][0]), o[3] = float(st.i[0][0]);
          continue;
        }
        const mlvq::GridCoord c = mlvq::grid_coord(g, d.lights.dirs[l], d.views.dirs[v]);
        o[0] = c.phi, o[1] = c.theta, o[2] = c.alpha, o[3] = c.beta;
      }
    // Always float: coordinates in node units (phi up to 64) would move by ~0.03 nodes in half.
    BTFC_ASSIGN_OR_RETURN(GpuTexture t, make_float_texture("measured_coord", TexFormat::rgba32f, uint32_t(nl), uint32_t(nv), 0, std::move(mc)));
    t.meaning = "grid coordinates (node units) of measured (light = x, view = y), as the model computes them";
    t.channel_meaning = {"phi", "theta", "alpha", "beta"};
    b.textures.push_back(std::move(t));
  }
  if (g.measured()) {  // arbitrary directions: the 9-lookup Delaunay blend of measured pairs, as the model
    BTFC_ASSIGN_OR_RETURN(auto dm, direction_maps(d, opt.direction_map));
    b.textures.push_back(std::move(dm.first));
    b.textures.push_back(std::move(dm.second));
  }
  for (const GpuTexture& t : b.textures)
    if (t.width > 2048 || t.height > 2048)
      b.warnings.push_back("texture '" + t.name + "' is " + std::to_string(t.width) + " x " + std::to_string(t.height) +
                           ": beyond the GLES 3.0 minimum MAX_TEXTURE_SIZE (2048)");
  if (B.subnormal)
    b.warnings.push_back(std::to_string(B.subnormal) + " nonzero scale factors stored as half subnormals (relative precision lost; --float avoids it)");

  b.evaluation = {
      {"scheme", h.scheme},
      {"channels", d.channels},
      {"grid", {{"nphi", g.nphi}, {"ntheta", g.ntheta}, {"nalpha", g.nalpha}, {"nbeta", g.nbeta}}},
      {"parameterisation",
       {{"phi", "view azimuth: atan2(wv.y, wv.x) in [0, 2 pi) (0 when wv.xy = 0); coordinate phi_v / (2 pi) * nphi, periodic"},
        {"theta", "view polar angle atan2(|wv.xy|, wv.z) (= acos(wv.z) for unit wv); coordinate theta_v / (pi / 2) * (ntheta - 1), clamped"},
        {"light_frame", "l' = Rz(-phi_v) wl with l'.z = max(wl.z, 0): (c wl.x + s wl.y, -s wl.x + c wl.y, max(wl.z, 0)), "
                        "(c, s) = (cos, sin) phi_v = wv.xy / |wv.xy| ((1, 0) when wv.xy = 0)"},
        {"alpha", "atan2(l'.x, l'.z) (0 when both are 0); coordinate (alpha + pi / 2) / pi * (nalpha - 1), clamped"},
        {"beta", "sin(beta) = l'.y / |l'| (0 when |l'| = 0); coordinate (sin(beta) + 1) / 2 * (nbeta - 1), clamped"},
        {"axis_of_one_node", "an axis with 1 node has coordinate 0"}}},
      {"interpolation",
       "4D multilinear over (beta, alpha, theta, phi): per axis i0 = floor(c), t = c - i0; phi wraps (i1 = (i0 + 1) mod nphi); "
       "clamped axes use i0 = n - 2, t = 1 at the top; weight of node m (bit 0 beta, 1 alpha, 2 theta, 3 phi) = "
       "w_beta * w_alpha * w_theta * w_phi; value = sum_m weight_m * rgb(node_m), nodes of weight 0 skipped"},
      {"node_chain",
       "e = texel_index(x, y), sc = texel_scale(x, y); for levels k = 4 .. s + 1: o = e * n_k + c_k, sc *= rgb<k>_scale[o], e = rgb<k>_index[o]; "
       "(li, ci) = merge[e]; for k = s .. 2: o = li * n_k + c_k, sc *= lum<k>_scale[o], li = lum<k>_index[o], ci = chroma<k>_index[ci * n_k + c_k]; "
       "L = sc * lum1[li * nbeta + c_1], (r, g) = chroma1[ci * nbeta + c_1]"},
      {"color", "RGB = 3 L (r, g, 1 - r - g) (L = (R + G + B) / 3, r = R / (R + G + B), g = G / (R + G + B))"},
      {"axes_of_levels", {{"1", "beta"}, {"2", "alpha"}, {"3", "theta"}, {"4", "phi"}}},
      {"books", books},
      {"merge", {{"texture", "merge"}, {"entries", h.merge_size()}, {"lum_book", ls}, {"chroma_book", cs}}},
      {"line_layout", "1D arrays: entry i at texel (i % width, i / width), width = min(count, " + std::to_string(k_line_width) +
                          "); decoded float = stored * scale"},
      {"measured", "btf_eval_measured(uv, l, v) evaluates at the grid coordinates measured_coord(l, v)"},
      {"layout", g.measured() ? "measured" : "grid"},
      {"directions", g.measured() ? "layout measured: the nodes are measured (light, view) pairs (node (phi, theta, alpha, beta) = view phi * ntheta + theta, "
                                    "light alpha * nbeta + beta, clamped to the last); btf_eval(wl, wv) = sum_ij wl_i wv_j btf_eval_measured(il_i, iv_j) "
                                    "over dir_index / dir_weight layers 0 (light), 1 (view)"
                                  : "layout grid: btf_eval(wl, wv) interpolates at mlvq_grid_coord(wl, wv)"},
      {"one_channel", d.channels == 1 ? "grey BTF: output (R, 0, 0)" : "RGB"}};
  b.glsl = shader(b);
  return b;
}

}  // namespace
}  // namespace mlvq_export

const Exporter k_mlvq_exporter = {"mlvq", &mlvq_export::build, &mlvq_export::emulate};

}  // namespace btfc::gpu
