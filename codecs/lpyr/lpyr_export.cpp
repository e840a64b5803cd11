// lpyr GPU export: the renderer of seed 001 sections 3.3-3.4 (eigen-Laplacian-BRDF map, PCA
// weight map with the level nesting, eq. 7 with continuous level of detail, YCbCr -> RGB).
//
// Textures (packing of the maps pinned in lpyr.h, "GPU tensors"; shader contract in export.h):
//   eigen_map      2D 3 nL x (lmax+1) nV, RGBA16F|32F: texel (j nL + l, k nV + v) = slot j of
//                  level k at (light l, view v); slots j = 0: Y e1..e4, 1: Y e5..e8,
//                  2: (Cb e1, Cb e2, Cr e1, Cr e2); value = stored * eigen_scale.
//   weight_map     2D, the paper's nested layout: level k's slots j = 0, 1, 2 at (ox_k, oy_k),
//                  (ox_k + w_k, oy_k), (ox_k, oy_k + h_k); value = stored * weight_scale[k][j]
//                  (per lane: the model's own per-component storage scale, so a half-precision
//                  model's weights are stored exactly in RGBA16F).
//   mean_map       2D nL x (lmax+1) nV: (Y, Cb, Cr) mean added at level k (the top block is mu',
//                  Phong evaluated at the measured directions); value = stored * mean_scale.
//   phong          2D 2 x 1 RGBA32F (only for a Phong top mean): (ka, kd, ks, alpha), (Cb, Cr).
//   direction_lut  2D array 32 x 32 x 2, R16UI: nearest measured light (layer 0) / view (1) of
//                  each parabolic cell (section 3.4 step 1).
//   dir_index / dir_weight   parabolic Delaunay maps (export.h), for btf_eval.
// btf_eval interpolates the measured directions by Delaunay (9 lookups, = the model's eval_dir);
// btf_eval_nearest_lod is the paper's own renderer (lpyr_export.h).
#include "codecs/lpyr/lpyr_export.h"
#include "codecs/lpyr/lpyr.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>

#include "codecs/lpyr/lpyr_internal.h"

namespace btfc::gpu {
namespace {

using lpyr::LpyrModel;

const auto glf = glsl_float;

// The constants of the shader, as the manifest's "evaluation" lists them.
struct Layout {
  int lmax = 0, nl = 0, nv = 0, dir_n = 0, lut_n = 0;
  bool phong = false;
  float eigen_scale = 1, mean_scale = 1;
  std::vector<std::array<int, 4>> lv;  // per level: w, h, ox, oy
  std::vector<float> ws;               // weight scale [(k * 3 + j) * 4 + lane]
  float m[3][3] = {};                  // YCbCr -> RGB, rgb_i = sum_c m[i][c] ycc_c
};

Layout layout_of(const ExportBundle& b) {
  const nlohmann::json& e = b.evaluation;
  Layout L;
  L.lmax = e.at("lmax").get<int>(), L.nl = e.at("lights").get<int>(), L.nv = e.at("views").get<int>();
  L.dir_n = e.at("direction_map_size").get<int>(), L.lut_n = e.at("lut_size").get<int>();
  L.phong = e.at("top_mean").get<std::string>() == "phong";
  L.eigen_scale = e.at("eigen_scale").get<float>(), L.mean_scale = e.at("mean_scale").get<float>();
  for (const nlohmann::json& lv : e.at("levels")) {
    L.lv.push_back({lv.at("size")[0].get<int>(), lv.at("size")[1].get<int>(), lv.at("weight_offset")[0].get<int>(),
                    lv.at("weight_offset")[1].get<int>()});
    for (const nlohmann::json& slot : lv.at("weight_scale"))
      for (const nlohmann::json& s : slot) L.ws.push_back(s.get<float>());
  }
  for (int i = 0; i < 3; ++i)
    for (int c = 0; c < 3; ++c) L.m[i][c] = e.at("ycbcr_to_rgb")[size_t(i)][size_t(c)].get<float>();
  return L;
}

const float* texel(const GpuTexture& t, int x, int y) { return &t.f[0][(size_t(y) * t.width + size_t(x)) * 4]; }

// The shader's lpyr_phong_mean(): (Phong Y, Cb, Cr) at the actual directions, in float.
void phong_mean(const GpuTexture& P, const Vec3& wl, const Vec3& wv, float* mean) {
  const float* p = texel(P, 0, 0);
  const float hx = wl.x + wv.x, hy = wl.y + wv.y, hz = wl.z + wv.z, n = std::sqrt(hx * hx + hy * hy + hz * hz);
  const float nh = n > 0 ? std::clamp(hz / n, 0.f, 1.f) : 0.f;
  mean[0] = p[0] + p[1] * std::clamp(wl.z, 0.f, 1.f) + p[2] * std::pow(std::max(nh, 1e-12f), p[3]);
  mean[1] = texel(P, 1, 0)[0], mean[2] = texel(P, 1, 0)[1];
}

// lpyr_ycc(): eq. 7 in YCbCr at texel (x, y), measured (l, v); `dirs` (wl, wv) selects the
// analytic Phong top mean of the nearest-direction renderer.
void ycc(const ExportBundle& b, const Layout& L, int x, int y, int l, int v, float lod, const Vec3* dirs, float* out) {
  const GpuTexture &D = *b.find("weight_map"), &E = *b.find("eigen_map"), &M = *b.find("mean_map");
  float acc[3] = {0, 0, 0};
  for (int k = int(std::floor(lod)); k <= L.lmax; ++k) {
    const float w = std::clamp(1.0f - lod + float(k), 0.0f, 1.0f);
    if (w == 0) continue;
    const std::array<int, 4>& s = L.lv[size_t(k)];
    const int px = x >> k, py = y >> k, row = k * L.nv + v;
    const int dx[3] = {s[2], s[2] + s[0], s[2]}, dy[3] = {s[3], s[3], s[3] + s[1]};
    float d[3][4], e[3][4];
    for (int j = 0; j < 3; ++j)
      for (int q = 0; q < 4; ++q) {
        d[j][q] = texel(D, dx[j] + px, dy[j] + py)[q] * L.ws[size_t((k * 3 + j) * 4 + q)];
        e[j][q] = texel(E, j * L.nl + l, row)[q] * L.eigen_scale;
      }
    float mean[3];
    for (int c = 0; c < 3; ++c) mean[c] = texel(M, l, row)[c] * L.mean_scale;
    if (dirs && L.phong && k == L.lmax) phong_mean(*b.find("phong"), dirs[0], dirs[1], mean);
    const float t[3] = {d[0][0] * e[0][0] + d[0][1] * e[0][1] + d[0][2] * e[0][2] + d[0][3] * e[0][3] + d[1][0] * e[1][0] +
                            d[1][1] * e[1][1] + d[1][2] * e[1][2] + d[1][3] * e[1][3],
                        d[2][0] * e[2][0] + d[2][1] * e[2][1], d[2][2] * e[2][2] + d[2][3] * e[2][3]};
    for (int c = 0; c < 3; ++c) acc[c] += w * (t[c] + mean[c]);
  }
  std::copy(acc, acc + 3, out);
}

void to_rgb(const Layout& L, const float* ycc, float* rgb) {
  for (int i = 0; i < 3; ++i) rgb[i] = L.m[i][0] * ycc[0] + L.m[i][1] * ycc[1] + L.m[i][2] * ycc[2];
}

void emulate(const ExportBundle& b, const ShaderQuery& q, float* rgb) { lpyr_emulate(b, q, 0.0f, LpyrRenderer::delaunay, rgb); }

}  // namespace

void lpyr_emulate(const ExportBundle& b, const ShaderQuery& q, float lod, LpyrRenderer r, float* rgb) {
  const Layout L = layout_of(b);
  lod = std::clamp(lod, 0.0f, float(L.lmax));
  int x, y;
  uv_texel(q.u, q.v, b.desc.width, b.desc.height, x, y);
  float c[3];
  if (q.light >= 0) {
    ycc(b, L, x, y, q.light, q.view, lod, nullptr, c);
    return to_rgb(L, c, rgb);
  }
  if (r == LpyrRenderer::nearest) {
    const GpuTexture& T = *b.find("direction_lut");
    int lx, ly, vx, vy;
    direction_cell(q.wl, L.lut_n, lx, ly);
    direction_cell(q.wv, L.lut_n, vx, vy);
    const int l = int(T.u[0][size_t(ly) * size_t(L.lut_n) + size_t(lx)]);
    const int v = int(T.u[0][(size_t(L.lut_n) + size_t(vy)) * size_t(L.lut_n) + size_t(vx)]);
    const Vec3 dirs[2] = {q.wl, q.wv};
    ycc(b, L, x, y, l, v, lod, dirs, c);
    return to_rgb(L, c, rgb);
  }
  emulate_delaunay(b, q.wl, q.wv, [&](int l, int v, float* out) {
    ycc(b, L, x, y, l, v, lod, nullptr, c);
    to_rgb(L, c, out);
  }, rgb);
}

namespace {

std::string shader(const ExportBundle& b, const Layout& L) {
  const int nlev = L.lmax + 1;
  std::string s = "#version 300 es\n// btfc lpyr reference shader: " + b.spec + "\n" +
                  "// Seed 001 eq. 7: sum_{k >= floor(lod)} w_k (D_k . E_k + mean_k) + mu', w_k = clamp(1 - lod + k, 0, 1), "
                  "then YCbCr -> RGB.\n"
                  "precision highp float;\nprecision highp int;\n"
                  "uniform highp sampler2D u_eigen_map;\nuniform highp sampler2D u_weight_map;\nuniform highp sampler2D u_mean_map;\n";
  if (L.phong) s += "uniform highp sampler2D u_phong;\n";
  s += "uniform highp usampler2DArray u_direction_lut;\nuniform highp usampler2DArray u_dir_index;\nuniform highp sampler2DArray u_dir_weight;\n";
  s += glsl_common();
  s += "const ivec2 SIZE = ivec2(" + std::to_string(b.desc.width) + ", " + std::to_string(b.desc.height) + ");\n";
  s += "const int LMAX = " + std::to_string(L.lmax) + ";\nconst int NL = " + std::to_string(L.nl) + ";\nconst int NV = " +
       std::to_string(L.nv) + ";\nconst int DIR_N = " + std::to_string(L.dir_n) + ";\nconst int LUT_N = " + std::to_string(L.lut_n) +
       ";\nconst float EIGEN_SCALE = " + glf(L.eigen_scale) + ";\nconst float MEAN_SCALE = " + glf(L.mean_scale) + ";\n";
  std::string sz, off, ws;
  for (int k = 0; k < nlev; ++k) {
    const std::array<int, 4>& v = L.lv[size_t(k)];
    sz += std::string(k ? ", " : "") + "ivec2(" + std::to_string(v[0]) + ", " + std::to_string(v[1]) + ")";
    off += std::string(k ? ", " : "") + "ivec2(" + std::to_string(v[2]) + ", " + std::to_string(v[3]) + ")";
    for (int j = 0; j < 3; ++j) {
      ws += std::string(k || j ? ",\n  " : "  ") + "vec4(";
      for (int q = 0; q < 4; ++q) ws += (q ? ", " : "") + glf(L.ws[size_t((k * 3 + j) * 4 + q)]);
      ws += ")";
    }
  }
  const std::string n = std::to_string(nlev), n3 = std::to_string(3 * nlev);
  s += "const ivec2 LEVEL_SIZE[" + n + "] = ivec2[" + n + "](" + sz + ");\n";
  s += "const ivec2 LEVEL_OFFSET[" + n + "] = ivec2[" + n + "](" + off + ");\n";
  s += "// weight_map scale per (level, slot): slots 0 Y e1-4, 1 Y e5-8, 2 (Cb e1, Cb e2, Cr e1, Cr e2)\n";
  s += "const vec4 WEIGHT_SCALE[" + n3 + "] = vec4[" + n3 + "](\n" + ws + ");\n";
  s += "const mat3 YCC_TO_RGB = mat3(";  // column-major: column c = RGB of unit YCbCr channel c
  for (int c = 0; c < 3; ++c)
    for (int i = 0; i < 3; ++i) s += glf(L.m[i][c]) + (c == 2 && i == 2 ? ");\n" : ", ");
  if (L.phong)
    s += "vec3 lpyr_phong_mean(vec3 wl, vec3 wv) {  // eq. 5 (Y) and eq. 6 (Cb, Cr constants)\n"
         "  vec4 p = texelFetch(u_phong, ivec2(0, 0), 0);\n  vec4 c = texelFetch(u_phong, ivec2(1, 0), 0);\n"
         "  vec3 h = wl + wv;\n  float n = length(h);\n  float nh = n > 0.0 ? clamp(h.z / n, 0.0, 1.0) : 0.0;\n"
         "  return vec3(p.x + p.y * clamp(wl.z, 0.0, 1.0) + p.z * pow(max(nh, 1e-12), p.w), c.x, c.y);\n}\n";
  s += "vec3 lpyr_ycc(ivec2 xy, int l, int v, float lod, bool phong_top, vec3 wl, vec3 wv) {\n"
       "  vec3 acc = vec3(0.0);\n"
       "  for (int k = int(floor(lod)); k <= LMAX; ++k) {\n"
       "    float w = clamp(1.0 - lod + float(k), 0.0, 1.0);\n"
       "    if (w == 0.0) continue;\n"
       "    ivec2 p = LEVEL_OFFSET[k] + ivec2(xy.x >> k, xy.y >> k);\n"
       "    vec4 d0 = texelFetch(u_weight_map, p, 0) * WEIGHT_SCALE[3 * k];\n"
       "    vec4 d1 = texelFetch(u_weight_map, p + ivec2(LEVEL_SIZE[k].x, 0), 0) * WEIGHT_SCALE[3 * k + 1];\n"
       "    vec4 d2 = texelFetch(u_weight_map, p + ivec2(0, LEVEL_SIZE[k].y), 0) * WEIGHT_SCALE[3 * k + 2];\n"
       "    int row = k * NV + v;\n"
       "    vec4 e0 = texelFetch(u_eigen_map, ivec2(l, row), 0) * EIGEN_SCALE;\n"
       "    vec4 e1 = texelFetch(u_eigen_map, ivec2(NL + l, row), 0) * EIGEN_SCALE;\n"
       "    vec4 e2 = texelFetch(u_eigen_map, ivec2(2 * NL + l, row), 0) * EIGEN_SCALE;\n"
       "    vec3 mean = texelFetch(u_mean_map, ivec2(l, row), 0).xyz * MEAN_SCALE;\n";
  if (L.phong) s += "    if (phong_top && k == LMAX) mean = lpyr_phong_mean(wl, wv);\n";
  s += "    acc += w * (vec3(dot(d0, e0) + dot(d1, e1), d2.x * e2.x + d2.y * e2.y, d2.z * e2.z + d2.w * e2.w) + mean);\n"
       "  }\n  return acc;\n}\n";
  s += "float btf_lod(float footprint) {  // seed 001 section 3.4 step 2 (range-based selection)\n"
       "  return min(float(LMAX), max(log2(max(footprint, 1e-30)), 0.0));\n}\n";
  s += "vec3 btf_eval_measured_lod(vec2 uv, int light, int view, float lod) {\n"
       "  return YCC_TO_RGB * lpyr_ycc(btfc_texel(uv, SIZE), light, view, clamp(lod, 0.0, float(LMAX)), false, vec3(0.0), vec3(0.0));\n}\n";
  s += glsl_delaunay_function("vec3 btf_eval_lod(vec2 uv, vec3 wl, vec3 wv, float lod)", "",
                              "btf_eval_measured_lod(uv, int(il[i]), int(iv[j]), lod)");
  s += "vec3 btf_eval_nearest_lod(vec2 uv, vec3 wl, vec3 wv, float lod) {  // seed 001 section 3.4\n"
       "  int l = int(texelFetch(u_direction_lut, ivec3(btfc_dir_cell(wl, LUT_N), 0), 0).r);\n"
       "  int v = int(texelFetch(u_direction_lut, ivec3(btfc_dir_cell(wv, LUT_N), 1), 0).r);\n"
       "  return YCC_TO_RGB * lpyr_ycc(btfc_texel(uv, SIZE), l, v, clamp(lod, 0.0, float(LMAX)), true, wl, wv);\n}\n";
  s += "vec3 btf_eval_measured(vec2 uv, int light, int view) { return btf_eval_measured_lod(uv, light, view, 0.0); }\n";
  s += "vec3 btf_eval(vec2 uv, vec3 wl, vec3 wv) { return btf_eval_lod(uv, wl, wv, 0.0); }\n";
  s += "#ifndef BTFC_NO_MAIN\nin vec2 v_uv;\nin vec3 v_wl;\nin vec3 v_wv;\nout vec4 btf_color;\n"
       "void main() { btf_color = vec4(btf_eval(v_uv, normalize(v_wl), normalize(v_wv)), 1.0); }\n#endif\n";
  return s;
}

const Tensor* tensor(const std::vector<Tensor>& ts, const char* name) {
  for (const Tensor& t : ts)
    if (t.name == name) return &t;
  return nullptr;
}

Result<ExportBundle> build(const Model& model, const ExportOptions& opt) {
  const auto* m = dynamic_cast<const LpyrModel*>(&model);
  if (!m) return invalid_argument("export: '" + model.spec() + "' is not an lpyr model");
  BTFC_ASSIGN_OR_RETURN(std::vector<Tensor> ts, m->gpu_tensors());  // unsupported beyond 8 Y / 2 Cb, Cr components
  const Tensor *te = tensor(ts, "eigen_map"), *tw = tensor(ts, "weight_map"), *tm = tensor(ts, "mean_map"), *tp = tensor(ts, "phong"),
               *tl = tensor(ts, "direction_lut");
  if (!te || !tw || !tm || !tl || (m->uses_phong() && !tp)) return codec_error("lpyr gpu_tensors: a map is missing");
  const BtfDesc& d = m->desc();
  Layout L;
  L.lmax = m->lmax(), L.nl = int(d.num_lights()), L.nv = int(d.num_views()), L.dir_n = opt.direction_map, L.phong = m->uses_phong();
  L.lut_n = int(tl->shape[1]);
  if (d.num_lights() > 65535 || d.num_views() > 65535) return unsupported("export: more than 65535 directions do not fit the R16UI lookup table");
  // Level sizes and weight-map offsets (the nesting of lpyr.h: level k + 1 starts at level k's far corner).
  for (int k = 0, ox = 0, oy = 0; k <= L.lmax; ++k) {
    const lpyr::LevelSize s = m->levels()[size_t(k)].size;
    L.lv.push_back({s.w, s.h, ox, oy});
    ox += s.w, oy += s.h;
  }
  const TexFormat ff = opt.half ? TexFormat::rgba16f : TexFormat::rgba32f;
  const bool rescale = opt.half && !opt.clamp_half;

  BTFC_ASSIGN_OR_RETURN(std::vector<float> em, te->to_f32());
  L.eigen_scale = rescale ? float(half_safe_scale(em)) : 1.0f;
  for (float& x : em) x /= L.eigen_scale;
  BTFC_ASSIGN_OR_RETURN(std::vector<float> wm, tw->to_f32());
  const size_t W2 = size_t(tw->shape[1]), H2 = size_t(tw->shape[0]);
  L.ws.assign(size_t(3 * (L.lmax + 1) * 4), 1.0f);
  for (int k = 0; k <= L.lmax; ++k)
    for (int j = 0; j < 3; ++j)
      for (int q = 0; q < 4; ++q) {
        // Per lane: max |d| over the slot (= the model's storage scale of that component).
        const std::array<int, 4>& s = L.lv[size_t(k)];
        const size_t x0 = size_t(s[2] + (j == 1 ? s[0] : 0)), y0 = size_t(s[3] + (j == 2 ? s[1] : 0));
        float mx = 0;
        for (size_t y = y0; y < y0 + size_t(s[1]); ++y)
          for (size_t x = x0; x < x0 + size_t(s[0]); ++x) mx = std::max(mx, std::abs(wm[(y * W2 + x) * 4 + size_t(q)]));
        const float sc = mx > 0 && std::isfinite(mx) ? mx : 1.0f;
        L.ws[size_t((k * 3 + j) * 4 + q)] = sc;
        for (size_t y = y0; y < y0 + size_t(s[1]); ++y)
          for (size_t x = x0; x < x0 + size_t(s[0]); ++x) wm[(y * W2 + x) * 4 + size_t(q)] /= sc;
      }
  BTFC_ASSIGN_OR_RETURN(std::vector<float> mm, tm->to_f32());
  L.mean_scale = rescale ? float(half_safe_scale(mm)) : 1.0f;
  for (float& x : mm) x /= L.mean_scale;
  for (int c = 0; c < 3; ++c) {  // the model's YCbCr -> RGB matrix, column by column
    const float unit[3] = {c == 0 ? 1.f : 0.f, c == 1 ? 1.f : 0.f, c == 2 ? 1.f : 0.f};
    float rgb[3];
    lpyr::ycbcr_to_rgb(unit, rgb);
    for (int i = 0; i < 3; ++i) L.m[i][c] = rgb[i];
  }

  ExportBundle b;
  BTFC_ASSIGN_OR_RETURN(GpuTexture E, make_float_texture("eigen_map", ff, uint32_t(te->shape[1]), uint32_t(te->shape[0]), 0, std::move(em)));
  E.scale = L.eigen_scale;
  E.meaning = "eigen-Laplacian-BRDFs: texel (j nL + l, k nV + v) = slot j of level k at light l, view v (seed 001 section 3.3, map 1)";
  E.channel_meaning = {"slot 0: Y e1 | 1: Y e5 | 2: Cb e1", "Y e2 | Y e6 | Cb e2", "Y e3 | Y e7 | Cr e1", "Y e4 | Y e8 | Cr e2"};
  BTFC_ASSIGN_OR_RETURN(GpuTexture D, make_float_texture("weight_map", ff, uint32_t(W2), uint32_t(H2), 0, std::move(wm)));
  D.meaning = "PCA weights, levels nested (level k's slots at offset, +(w_k, 0), +(0, h_k)); value = stored * evaluation.levels[k].weight_scale[slot]";
  D.channel_meaning = E.channel_meaning;
  BTFC_ASSIGN_OR_RETURN(GpuTexture M, make_float_texture("mean_map", ff, uint32_t(L.nl), uint32_t((L.lmax + 1) * L.nv), 0, std::move(mm)));
  M.scale = L.mean_scale;
  M.meaning = "mean added at level k, texel (l, k nV + v); top block = mu' (Phong / constants or stored means) at the measured directions";
  M.channel_meaning = {"Y", "Cb", "Cr", "unused"};
  b.textures.push_back(std::move(E));
  b.textures.push_back(std::move(D));
  b.textures.push_back(std::move(M));
  if (L.phong) {
    BTFC_ASSIGN_OR_RETURN(std::vector<float> p, tp->to_f32());
    p.insert(p.end(), {0.f, 0.f});
    BTFC_ASSIGN_OR_RETURN(GpuTexture P, make_float_texture("phong", TexFormat::rgba32f, 2, 1, 0, std::move(p)));
    P.meaning = "top-level mean: Y = ka + kd (N.L) + ks (N.H)^alpha (eq. 5), Cb, Cr constants (eq. 6)";
    P.channel_meaning = {"ka | Cb", "kd | Cr", "ks | unused", "alpha | unused"};
    b.textures.push_back(std::move(P));
  }
  std::vector<uint32_t> lut(tl->count());
  std::copy(tl->bytes.begin(), tl->bytes.end(), reinterpret_cast<uint8_t*>(lut.data()));
  BTFC_ASSIGN_OR_RETURN(GpuTexture T, make_uint_texture("direction_lut", TexFormat::r16_uint, uint32_t(L.lut_n), uint32_t(L.lut_n), 2, std::move(lut)));
  T.meaning = "nearest measured direction of each parabolic cell (layer 0 lights, 1 views), seed 001 section 3.4 step 1";
  T.channel_meaning = {"direction index"};
  b.textures.push_back(std::move(T));
  BTFC_ASSIGN_OR_RETURN(auto dm, direction_maps(d, opt.direction_map));
  b.textures.push_back(std::move(dm.first));
  b.textures.push_back(std::move(dm.second));

  nlohmann::json levels = nlohmann::json::array();
  for (int k = 0; k <= L.lmax; ++k) {
    nlohmann::json ws = nlohmann::json::array();
    for (int j = 0; j < 3; ++j) {
      const float* w = &L.ws[size_t((k * 3 + j) * 4)];
      ws.push_back({w[0], w[1], w[2], w[3]});
    }
    const std::array<int, 4>& s = L.lv[size_t(k)];
    levels.push_back({{"size", {s[0], s[1]}}, {"weight_offset", {s[2], s[3]}}, {"weight_scale", ws}});
  }
  b.evaluation = {
      {"lmax", L.lmax}, {"lights", L.nl}, {"views", L.nv}, {"levels", levels},
      {"eigen_scale", L.eigen_scale}, {"mean_scale", L.mean_scale}, {"top_mean", L.phong ? "phong" : "stored"},
      {"ycbcr_to_rgb", {{L.m[0][0], L.m[0][1], L.m[0][2]}, {L.m[1][0], L.m[1][1], L.m[1][2]}, {L.m[2][0], L.m[2][1], L.m[2][2]}}},
      {"slots", "j = 0: Y e1..e4, 1: Y e5..e8, 2: (Cb e1, Cb e2, Cr e1, Cr e2); missing components are 0"},
      {"formula", "ycc(x, y, l, v; lod) = sum_{k = floor(lod)}^{lmax} w_k (Y: dot(d_k0, e_k0) + dot(d_k1, e_k1), Cb: d_k2.xy . e_k2.xy, "
                  "Cr: d_k2.zw . e_k2.zw + mean_map(l, k nV + v)), w_k = clamp(1 - lod + k, 0, 1), d_kj = weight_map(LEVEL_OFFSET_k + "
                  "slot offset + (x >> k, y >> k)) * weight_scale, e_kj = eigen_map(j nL + l, k nV + v) * eigen_scale; rgb = ycbcr_to_rgb ycc"},
      {"lod", "btf_eval / btf_eval_measured use lod 0 (full detail, = the model's eval); btf_eval_lod, btf_eval_measured_lod and "
              "btf_eval_nearest_lod take lod in [0, lmax] (clamped); btf_lod(footprint) = min(lmax, max(log2(footprint), 0)) is the "
              "paper's range-based choice (footprint = texels per pixel)"},
      {"interpolation", "btf_eval: Delaunay in parabolic coordinates, sum_ij wl_i wv_j rgb(il_i, iv_j) over dir_index / dir_weight "
                        "(cell = floor((p / 2 + 1 / 2) n), p = (x, y) / (1 + z))"},
      {"nearest_renderer", "btf_eval_nearest_lod (seed 001 section 3.4): (l, v) = direction_lut at the cells of wl, wv (n = lut_size); "
                           "top-level mean = Phong at the actual (wl, wv) when top_mean = phong, else mean_map"},
      {"storage", "rgba16f: a half-precision model's eigen map and weights are stored exactly (weights divided by the model's own "
                  "per-component scales), the means are rounded to half (relative 2^-11); rgba32f: exact to float rounding"},
      {"lut_size", L.lut_n}, {"direction_map_size", opt.direction_map}};
  b.desc = d, b.spec = model.spec();
  b.glsl = shader(b, L);
  return b;
}

}  // namespace

const Exporter k_lpyr_exporter = {"lpyr", &build, &emulate};

}  // namespace btfc::gpu
