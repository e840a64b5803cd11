// lpca GPU export: the local-PCA BTF of seed 002 section 3 as textures, its SH coefficients
// (section 4.3) and the PRT maps of section 5 (fixed lighting).
//
// Textures (shader contract in export.h; C = components c, P = ceil(c / 4), K = clusters):
//   cluster_index  2D W x H, R16UI: k(x).
//   weights        2D array W x H x P, RGBA16F|32F: components 4j..4j+3 of the texel's PCA
//                  weights in layer j, divided by cluster_scale (|stored| <= 1).
//   cluster_scale  2D (1 + P) x K, RGBA32F: texel (0, k).r = mean scale of cluster k, texel
//                  (1 + j, k) = weight scales of components 4j..4j+3 (max |.| over the cluster,
//                  which for a half-precision model are its own storage scales, so its means and
//                  weights are stored exactly in RGBA16F).
//   eigen_brdfs    2D array (C + 1) nL x nV x K, RGBA16F|32F: texel (m nL + l, v, k) = colour
//                  channels of cluster k's row m at (light l, view v); m = 0 the mean / mean scale,
//                  m >= 1 eigen-BRDF m (orthonormal, |.| <= 1).
//   eigen_sh       2D array (C + 1) S x nV ch x K (S = ceil(n^2 / 4)), RGBA16F|32F: texel
//                  (m S + s, v ch + c, k) = SH coefficients 4s..4s+3 of row m's view-v slice,
//                  channel c, projected over the lights (e^v_{m,k}); row 0 / mean scale;
//                  value = stored * scale (the texture's).
//   prt            (environment attached) 2D array 16 (C + 1) x 16 x K, RGBA8: texel
//                  (16 m + i, j, k) = lambda_{m,k} at parabolic view cell (i, j) as 8 bits,
//                  lambda = (2 stored - 1) prt_scale[m == 0 ? 0 : 1]; a 1-channel BTF is grey.
//   dir_index / dir_weight   parabolic Delaunay maps for btf_eval.
#include "codecs/lpca/lpca_export.h"
#include "codecs/lpca/lpca.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "codecs/lpca/lpca_model.h"
#include "core/sh.h"

namespace btfc::gpu {
namespace {

using lpca::LpcaModel;
constexpr int k_prt_n = 16;

const auto glf = glsl_float;

struct Layout {
  int C = 0, P = 0, nl = 0, nv = 0, nc = 0, dir_n = 0;
  bool prt = false;
  float prt_scale[2] = {1, 1};
};

Layout layout_of(const ExportBundle& b) {
  const nlohmann::json& e = b.evaluation;
  Layout L;
  L.C = e.at("components").get<int>(), L.P = (L.C + 3) / 4;
  L.nl = e.at("lights").get<int>(), L.nv = e.at("views").get<int>(), L.nc = b.desc.channels;
  L.dir_n = e.at("direction_map_size").get<int>();
  L.prt = e.contains("prt_scale");
  if (L.prt) L.prt_scale[0] = e.at("prt_scale")[0].get<float>(), L.prt_scale[1] = e.at("prt_scale")[1].get<float>();
  return L;
}

const float* texel(const GpuTexture& t, int layer, int x, int y) {
  return &t.f[0][((size_t(layer) * t.height + size_t(y)) * t.width + size_t(x)) * 4];
}

// lpca_measured(): mean + sum_i w_i E_i at texel (x, y), measured (l, v), in the model's order.
void measured(const ExportBundle& b, const Layout& L, int x, int y, int l, int v, float* rgb) {
  const GpuTexture &I = *b.find("cluster_index"), &S = *b.find("cluster_scale"), &W = *b.find("weights"), &E = *b.find("eigen_brdfs");
  const int k = int(I.u[0][size_t(y) * I.width + size_t(x)]);
  const float* mean = texel(E, k, l, v);
  const float ms = texel(S, 0, 0, k)[0];
  float s[3] = {mean[0] * ms, mean[1] * ms, mean[2] * ms};
  for (int j = 0; j < L.P; ++j) {
    const float *w = texel(W, j, x, y), *ws = texel(S, 0, 1 + j, k);
    for (int q = 0; q < 4 && 4 * j + q < L.C; ++q) {
      const float wq = w[q] * ws[q];
      const float* e = texel(E, k, (1 + 4 * j + q) * L.nl + l, v);
      for (int c = 0; c < 3; ++c) s[c] += wq * e[c];
    }
  }
  for (int c = 0; c < 3; ++c) rgb[c] = c < L.nc ? s[c] : 0.f;
}

void emulate(const ExportBundle& b, const ShaderQuery& q, float* rgb) {
  const Layout L = layout_of(b);
  int x, y;
  uv_texel(q.u, q.v, b.desc.width, b.desc.height, x, y);
  if (q.light >= 0) return measured(b, L, x, y, q.light, q.view, rgb);
  emulate_delaunay(b, q.wl, q.wv, [&](int l, int v, float* out) { measured(b, L, x, y, l, v, out); }, rgb);
}

}  // namespace

void lpca_emulate_relit(const ExportBundle& b, float u, float v, const Vec3& wv, float* rgb) {
  const Layout L = layout_of(b);
  const GpuTexture &I = *b.find("cluster_index"), &S = *b.find("cluster_scale"), &W = *b.find("weights"), &T = *b.find("prt");
  int x, y;
  uv_texel(u, v, b.desc.width, b.desc.height, x, y);
  const int k = int(I.u[0][size_t(y) * I.width + size_t(x)]);
  // Bilinear position in the parabolic map: texel centres at ((i + 0.5) / 8 - 1), clamped to the edge.
  const float s = 1.0f / (1.0f + std::max(wv.z, 0.0f));
  const float tx = (wv.x * s * 0.5f + 0.5f) * float(k_prt_n) - 0.5f, ty = (wv.y * s * 0.5f + 0.5f) * float(k_prt_n) - 0.5f;
  const float fx0 = std::floor(tx), fy0 = std::floor(ty), fx = tx - fx0, fy = ty - fy0;
  const int x0 = std::clamp(int(fx0), 0, k_prt_n - 1), x1 = std::clamp(int(fx0) + 1, 0, k_prt_n - 1);
  const int y0 = std::clamp(int(fy0), 0, k_prt_n - 1), y1 = std::clamp(int(fy0) + 1, 0, k_prt_n - 1);
  auto lambda = [&](int m, int c) {
    auto at = [&](int i, int j) { return 2.0f * texel(T, k, m * k_prt_n + i, j)[c] - 1.0f; };
    const float a = at(x0, y0) + (at(x1, y0) - at(x0, y0)) * fx, bb = at(x0, y1) + (at(x1, y1) - at(x0, y1)) * fx;
    return (a + (bb - a) * fy) * L.prt_scale[m == 0 ? 0 : 1];
  };
  float acc[3];
  for (int c = 0; c < 3; ++c) acc[c] = lambda(0, c);
  for (int j = 0; j < L.P; ++j) {
    const float *w = texel(W, j, x, y), *ws = texel(S, 0, 1 + j, k);
    for (int q = 0; q < 4 && 4 * j + q < L.C; ++q) {
      const float wq = w[q] * ws[q];
      for (int c = 0; c < 3; ++c) acc[c] += wq * lambda(1 + 4 * j + q, c);
    }
  }
  std::copy(acc, acc + 3, rgb);
}

namespace {

std::string shader(const ExportBundle& b, const Layout& L) {
  std::string s = "#version 300 es\n// btfc lpca reference shader: " + b.spec + "\n" +
                  "// Seed 002 section 3: B(x) = mean_k + sum_i w_i(x) E_{i,k}, k = cluster_index(x); Delaunay direction blend.\n"
                  "precision highp float;\nprecision highp int;\n"
                  "uniform highp usampler2D u_cluster_index;\nuniform highp sampler2DArray u_weights;\n"
                  "uniform highp sampler2D u_cluster_scale;\nuniform highp sampler2DArray u_eigen_brdfs;\n"
                  "uniform highp sampler2DArray u_eigen_sh;\n";
  if (L.prt) s += "uniform highp sampler2DArray u_prt;\n";
  s += "uniform highp usampler2DArray u_dir_index;\nuniform highp sampler2DArray u_dir_weight;\n";
  s += glsl_common();
  s += "const ivec2 SIZE = ivec2(" + std::to_string(b.desc.width) + ", " + std::to_string(b.desc.height) + ");\n";
  s += "const int C = " + std::to_string(L.C) + ";  // components per cluster\nconst int P = " + std::to_string(L.P) +
       ";  // weight layers\nconst int NL = " + std::to_string(L.nl) + ";\nconst int DIR_N = " + std::to_string(L.dir_n) + ";\n";
  // Channels beyond the BTF's are 0 (contract); a 1-channel BTF keeps R only.
  const std::string mask = "vec3(1.0, " + std::string(L.nc > 1 ? "1.0" : "0.0") + ", " + (L.nc > 2 ? "1.0" : "0.0") + ")";
  s += "const vec3 CHANNELS = " + mask + ";\n";
  s += "vec3 lpca_measured(ivec2 xy, int l, int v) {\n"
       "  int k = int(texelFetch(u_cluster_index, xy, 0).r);\n"
       "  vec3 s = texelFetch(u_eigen_brdfs, ivec3(l, v, k), 0).rgb * texelFetch(u_cluster_scale, ivec2(0, k), 0).r;\n"
       "  for (int j = 0; j < P; ++j) {\n"
       "    vec4 w = texelFetch(u_weights, ivec3(xy, j), 0) * texelFetch(u_cluster_scale, ivec2(1 + j, k), 0);\n"
       "    for (int q = 0; q < 4 && 4 * j + q < C; ++q)\n"
       "      s += w[q] * texelFetch(u_eigen_brdfs, ivec3((1 + 4 * j + q) * NL + l, v, k), 0).rgb;\n"
       "  }\n  return s * CHANNELS;\n}\n";
  s += "vec3 btf_eval_measured(vec2 uv, int light, int view) { return lpca_measured(btfc_texel(uv, SIZE), light, view); }\n";
  s += glsl_delaunay_function("vec3 btf_eval(vec2 uv, vec3 wl, vec3 wv)", "  ivec2 xy = btfc_texel(uv, SIZE);\n",
                              "lpca_measured(xy, int(il[i]), int(iv[j]))");
  if (L.prt) {
    s += "const vec2 PRT_SCALE = vec2(" + glf(L.prt_scale[0]) + ", " + glf(L.prt_scale[1]) + ");  // means, eigen-BRDFs\n";
    s += "vec3 lpca_prt(int k, int m, ivec2 i0, ivec2 i1, vec2 f) {  // bilinear, decoded before blending\n"
         "  int o = 16 * m;\n"
         "  vec3 a = 2.0 * texelFetch(u_prt, ivec3(o + i0.x, i0.y, k), 0).rgb - 1.0;\n"
         "  vec3 b = 2.0 * texelFetch(u_prt, ivec3(o + i1.x, i0.y, k), 0).rgb - 1.0;\n"
         "  vec3 c = 2.0 * texelFetch(u_prt, ivec3(o + i0.x, i1.y, k), 0).rgb - 1.0;\n"
         "  vec3 d = 2.0 * texelFetch(u_prt, ivec3(o + i1.x, i1.y, k), 0).rgb - 1.0;\n"
         "  vec3 ab = a + (b - a) * f.x, cd = c + (d - c) * f.x;\n"
         "  return (ab + (cd - ab) * f.y) * (m == 0 ? PRT_SCALE.x : PRT_SCALE.y);\n}\n";
    s += "vec3 btf_relit(vec2 uv, vec3 wv) {  // seed 002 eq. 3 under the exported environment\n"
         "  ivec2 xy = btfc_texel(uv, SIZE);\n"
         "  int k = int(texelFetch(u_cluster_index, xy, 0).r);\n"
         "  vec2 t = (wv.xy * (1.0 / (1.0 + max(wv.z, 0.0))) * 0.5 + 0.5) * 16.0 - 0.5;\n"
         "  vec2 t0 = floor(t), f = t - t0;\n"
         "  ivec2 i0 = clamp(ivec2(t0), ivec2(0), ivec2(15)), i1 = clamp(ivec2(t0) + 1, ivec2(0), ivec2(15));\n"
         "  vec3 acc = lpca_prt(k, 0, i0, i1, f);\n"
         "  for (int j = 0; j < P; ++j) {\n"
         "    vec4 w = texelFetch(u_weights, ivec3(xy, j), 0) * texelFetch(u_cluster_scale, ivec2(1 + j, k), 0);\n"
         "    for (int q = 0; q < 4 && 4 * j + q < C; ++q) acc += w[q] * lpca_prt(k, 1 + 4 * j + q, i0, i1, f);\n"
         "  }\n  return acc;\n}\n";
  }
  s += "#ifndef BTFC_NO_MAIN\nin vec2 v_uv;\nin vec3 v_wl;\nin vec3 v_wv;\nout vec4 btf_color;\n"
       "void main() { btf_color = vec4(btf_eval(v_uv, normalize(v_wl), normalize(v_wv)), 1.0); }\n#endif\n";
  return s;
}

Result<ExportBundle> build(const Model& model, const ExportOptions& opt) {
  const auto* m = dynamic_cast<const LpcaModel*>(&model);
  if (!m) return invalid_argument("export: '" + model.spec() + "' is not an lpca model");
  const BtfDesc& d = m->desc();
  if (d.channels > 3) return unsupported("export: lpca with " + std::to_string(d.channels) + " channels (the shader returns RGB: at most 3)");
  if (d.num_lights() > 65535 || d.num_views() > 65535) return unsupported("export: more than 65535 directions");
  // A scene keeps only the measured directions inside its cones (core/scene.h); the
  // textures then index the kept directions, "light_indices" / "view_indices" map them back.
  const std::vector<int> ls = directions_in_cone(d.lights, opt.scene ? opt.scene->light_cone : std::nullopt);
  const std::vector<int> vs = directions_in_cone(d.views, opt.scene ? opt.scene->view_cone : std::nullopt);
  Layout L;
  L.C = m->components(), L.P = (L.C + 3) / 4, L.nl = int(ls.size()), L.nv = int(vs.size()), L.nc = d.channels;
  L.dir_n = opt.direction_map;
  const int K = m->clusters(), C = L.C, nc = L.nc;
  const size_t W = size_t(d.width), H = size_t(d.height), N = W * H, nl = size_t(L.nl), nv = size_t(L.nv);
  const TexFormat ff = opt.half ? TexFormat::rgba16f : TexFormat::rgba32f;
  const lpca::MatrixXfR &T = m->table(), &Wt = m->weights();
  const std::vector<uint32_t>& cl = m->cluster_of();

  // Per-cluster scales: max |mean| and max |w_i| over the cluster's texels (1 when zero).
  std::vector<float> ms(size_t(K), 0.f), ws(size_t(K) * size_t(C), 0.f);
  for (int k = 0; k < K; ++k) ms[size_t(k)] = T.row(Eigen::Index(k) * (C + 1)).cwiseAbs().maxCoeff();
  for (size_t t = 0; t < N; ++t)
    for (int i = 0; i < C; ++i) ws[cl[t] * size_t(C) + size_t(i)] = std::max(ws[cl[t] * size_t(C) + size_t(i)], std::abs(Wt(Eigen::Index(t), i)));
  for (float& s : ms) s = s > 0 && std::isfinite(s) ? s : 1.f;
  for (float& s : ws) s = s > 0 && std::isfinite(s) ? s : 1.f;

  std::vector<uint32_t> idx(cl.begin(), cl.end());
  std::vector<float> sc(size_t(K) * size_t(1 + L.P) * 4, 0.f), wm(size_t(L.P) * N * 4, 0.f);
  for (int k = 0; k < K; ++k) {
    sc[size_t(k) * size_t(1 + L.P) * 4] = ms[size_t(k)];
    for (int i = 0; i < C; ++i) sc[(size_t(k) * size_t(1 + L.P) + 1 + size_t(i / 4)) * 4 + size_t(i % 4)] = ws[size_t(k) * size_t(C) + size_t(i)];
  }
  for (size_t t = 0; t < N; ++t)
    for (int i = 0; i < C; ++i) wm[(size_t(i / 4) * N + t) * 4 + size_t(i % 4)] = Wt(Eigen::Index(t), i) / ws[cl[t] * size_t(C) + size_t(i)];
  // Eigen-BRDF table: (m nL + l, v, k) -> channels.
  const size_t ew = size_t(C + 1) * nl;
  std::vector<float> eb(ew * nv * size_t(K) * 4, 0.f);
  for (int k = 0; k < K; ++k)
    for (int mm = 0; mm <= C; ++mm) {
      const auto row = T.row(Eigen::Index(k) * (C + 1) + mm);
      const float div = mm == 0 ? ms[size_t(k)] : 1.f;
      for (size_t v = 0; v < nv; ++v)
        for (size_t l = 0; l < nl; ++l)
          for (int c = 0; c < nc; ++c)
            eb[((size_t(k) * nv + v) * ew + size_t(mm) * nl + l) * 4 + size_t(c)] =
                row(Eigen::Index(d.row(size_t(ls[l]), size_t(vs[v]), size_t(c)))) / div;
    }
  // SH coefficients: (m S + s, v ch + c, k) -> 4 coefficients.
  const int n2 = sh::num_coeffs(m->config().sh_order), S = (n2 + 3) / 4;
  const size_t shw = size_t(C + 1) * size_t(S), shh = nv * size_t(nc);
  std::vector<float> esh(shw * shh * size_t(K) * 4, 0.f);
  const std::vector<float>& src = m->eigen_sh();
  for (int k = 0; k < K; ++k)
    for (int mm = 0; mm <= C; ++mm) {
      const size_t r = size_t(k) * size_t(C + 1) + size_t(mm);
      const float div = mm == 0 ? ms[size_t(k)] : 1.f;
      for (size_t v = 0; v < nv; ++v)
        for (int c = 0; c < nc; ++c)
          for (int j = 0; j < n2; ++j)
            esh[((size_t(k) * shh + v * size_t(nc) + size_t(c)) * shw + size_t(mm) * size_t(S) + size_t(j / 4)) * 4 + size_t(j % 4)] =
                src[((r * d.num_views() + size_t(vs[v])) * size_t(nc) + size_t(c)) * size_t(n2) + size_t(j)] / div;
    }
  const double sh_scale = opt.half && !opt.clamp_half ? half_safe_scale(esh) : 1.0;
  for (float& x : esh) x = float(x / sh_scale);

  ExportBundle b;
  BTFC_ASSIGN_OR_RETURN(GpuTexture TI, make_uint_texture("cluster_index", TexFormat::r16_uint, uint32_t(W), uint32_t(H), 0, std::move(idx)));
  TI.meaning = "cluster k(x) of each texel (seed 002 section 3)";
  TI.channel_meaning = {"cluster"};
  BTFC_ASSIGN_OR_RETURN(GpuTexture TW, make_float_texture("weights", ff, uint32_t(W), uint32_t(H), uint32_t(L.P), std::move(wm)));
  TW.meaning = "PCA weights, components 4j..4j+3 in layer j; value = stored * cluster_scale(1 + j, k(x))";
  TW.channel_meaning = {"component 4j", "component 4j+1", "component 4j+2", "component 4j+3"};
  BTFC_ASSIGN_OR_RETURN(GpuTexture TS, make_float_texture("cluster_scale", TexFormat::rgba32f, uint32_t(1 + L.P), uint32_t(K), 0, std::move(sc)));
  TS.meaning = "row k: texel 0 = (mean scale, 0, 0, 0), texel 1 + j = weight scales of components 4j..4j+3";
  TS.channel_meaning = TW.channel_meaning;
  BTFC_ASSIGN_OR_RETURN(GpuTexture TE, make_float_texture("eigen_brdfs", ff, uint32_t(ew), uint32_t(nv), uint32_t(K), std::move(eb)));
  TE.meaning = "layer k, texel (m nL + l, v): row m of cluster k (0: mean / mean scale, m >= 1: eigen-BRDF m) at light l, view v";
  TE.channel_meaning = {"R", "G", "B", "unused"};
  BTFC_ASSIGN_OR_RETURN(GpuTexture TH, make_float_texture("eigen_sh", ff, uint32_t(shw), uint32_t(shh), uint32_t(K), std::move(esh)));
  TH.scale = sh_scale;
  TH.meaning = "layer k, texel (m S + s, v channels + c): SH coefficients 4s..4s+3 of e^v_{m,k} (row 0 / mean scale); value = stored * scale";
  TH.channel_meaning = {"coefficient 4s", "coefficient 4s+1", "coefficient 4s+2", "coefficient 4s+3"};
  b.textures.push_back(std::move(TI));
  b.textures.push_back(std::move(TW));
  b.textures.push_back(std::move(TS));
  b.textures.push_back(std::move(TE));
  b.textures.push_back(std::move(TH));

  BTFC_ASSIGN_OR_RETURN(std::vector<Tensor> ts, m->gpu_tensors());
  const Tensor *tq = nullptr, *tsc = nullptr;
  for (const Tensor& t : ts) {
    if (t.name == "prt") tq = &t;
    if (t.name == "prt_scale") tsc = &t;
  }
  if (tq) {
    if (!tsc || tq->dtype != DType::u8 || tq->shape != std::vector<uint64_t>{uint64_t(K), uint64_t(C + 1), k_prt_n, k_prt_n, uint64_t(nc)})
      return codec_error("export: lpca PRT tensors have an unexpected shape");
    BTFC_ASSIGN_OR_RETURN(std::vector<float> ps, tsc->to_f32());
    L.prt = true, L.prt_scale[0] = ps[0], L.prt_scale[1] = ps[1];
    const size_t pw = size_t(k_prt_n) * size_t(C + 1);
    std::vector<float> pm(pw * k_prt_n * size_t(K) * 4, 0.f);
    for (int k = 0; k < K; ++k)
      for (int mm = 0; mm <= C; ++mm)
        for (int j = 0; j < k_prt_n; ++j)
          for (int i = 0; i < k_prt_n; ++i)
            for (int c = 0; c < 3; ++c) {
              const size_t at = (((size_t(k) * size_t(C + 1) + size_t(mm)) * k_prt_n + size_t(j)) * k_prt_n + size_t(i)) * size_t(nc) + size_t(std::min(c, nc - 1));
              pm[((size_t(k) * k_prt_n + size_t(j)) * pw + size_t(mm * k_prt_n + i)) * 4 + size_t(c)] = float(tq->bytes[at]) / 255.f;
            }
    BTFC_ASSIGN_OR_RETURN(GpuTexture TP, make_float_texture("prt", TexFormat::rgba8_unorm, uint32_t(pw), k_prt_n, uint32_t(K), std::move(pm)));
    TP.scale = 2, TP.bias = -1;  // decoded 2 u - 1 in [-1, 1], times the category's prt_scale
    TP.meaning = "PRT lambda_{m,k}(view) (seed 002 section 5.1): layer k, texel (16 m + i, j) = parabolic view cell (i, j); "
                 "lambda = (2 stored - 1) prt_scale[m == 0 ? 0 : 1]";
    TP.channel_meaning = {"R", "G", "B", "unused"};
    b.textures.push_back(std::move(TP));
  }
  BtfDesc dsub = d;  // the kept directions, for the Delaunay maps
  dsub.lights.dirs.clear(), dsub.views.dirs.clear();
  for (int l : ls) dsub.lights.dirs.push_back(d.lights.dirs[size_t(l)]);
  for (int v : vs) dsub.views.dirs.push_back(d.views.dirs[size_t(v)]);
  BTFC_ASSIGN_OR_RETURN(auto dm, direction_maps(dsub, opt.direction_map));
  b.textures.push_back(std::move(dm.first));
  b.textures.push_back(std::move(dm.second));

  b.evaluation = {
      {"clusters", K}, {"components", C}, {"weight_layers", L.P}, {"lights", L.nl}, {"views", L.nv}, {"channels", nc},
      {"sh_order", m->config().sh_order}, {"sh_coefficients", n2}, {"sh_texels_per_row", S},
      {"formula", "k = cluster_index(x, y); rgb = eigen_brdfs[k](l, v) * cluster_scale(0, k).r + sum_{i < C} w_i eigen_brdfs[k]((1 + i) nL + l, v), "
                  "w_i = weights[i / 4](x, y)[i % 4] * cluster_scale(1 + i / 4, k)[i % 4]"},
      {"interpolation", "btf_eval: Delaunay in parabolic coordinates, sum_ij wl_i wv_j rgb(il_i, iv_j) over dir_index / dir_weight"},
      {"sh", "relighting under an SH environment a (sample frame, order sh_order, seed 002 eq. 2): L(x, v) = sum_{m=0..C} beta_m "
             "<e^v_{m,k}, a>, beta_0 = cluster_scale(0, k).r (row 0 is stored / mean scale), beta_m = w_{m-1}; views between the "
             "measured ones by Delaunay weights (dir_index layer 1)"},
      {"storage", "means and weights divided by cluster_scale, eigen-BRDFs orthonormal: every stored value is within [-1, 1] (no half "
                  "overflow); rgba16f is exact for a half-precision model (cluster_scale = its storage scales), else rounded (relative "
                  "2^-11); eigen_sh is rounded; rgba32f: exact to float rounding; prt: 8 bits as the model quantizes it"},
      {"direction_map_size", opt.direction_map},
      {"light_indices", ls},
      {"view_indices", vs}};
  if (opt.scene)
    b.scene_report = {{"kept", "the measured directions inside the scene's cones (widened by the longest Delaunay edge); all "
                               "clusters, components and texels (lpca has no mip levels)"},
                      {"lights_kept", ls.size()},
                      {"views_kept", vs.size()},
                      {"predicted_added_rel_error", 0.0}};
  if (L.prt) {
    b.evaluation["prt_scale"] = {L.prt_scale[0], L.prt_scale[1]};
    b.evaluation["prt"] = "btf_relit(uv, wv) = lambda_0 + sum_i w_i lambda_{1+i} (seed 002 eq. 3, fixed lighting), lambda_m = (2 prt - 1) "
                          "prt_scale[m == 0 ? 0 : 1], bilinear between parabolic cell centres ((i + 0.5) / 8 - 1), clamped to the edge; "
                          "views in the sample frame";
  }
  b.desc = d, b.spec = model.spec();
  b.glsl = shader(b, L);
  return b;
}

}  // namespace

const Exporter k_lpca_exporter = {"lpca", &build, &emulate};

}  // namespace btfc::gpu
