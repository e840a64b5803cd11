// fmf GPU export: the renderer of seed 000 section 4 (eigen-ABRDFs x eigen-textures, Delaunay
// direction interpolation in parabolic coordinates, 9 lookups).
//
// Textures (codecs/gpu_export.h for the shader contract):
//   eigen_texture  2D array W x H, sum_b ceil(C_b / 4) layers, RGBA = components 4j..4j+3 of
//                  block b's SxV (eigen-textures, V Sigma) / per-component scale; full mip chain (box filter:
//                  a mip level of the eigen-textures is exactly the mip level of the BTF).
//   eigen_abrdf    2D array nL x nV (x = light, y = view), layer aoff_b + r * K_b + j holds
//                  components 4j..4j+3 of block b's U row for (light, view, colour r).
//   dir_index / dir_weight   parabolic Delaunay maps (layer 0 lights, 1 views).
// Blocks: color=rgb one block whose rows are (colour r, light, view); color=dfmf blocks y, u, v
// (rows (light, view)) decoded in the shader as the model does (Ylog, U/Y, V/Y -> RGB).
#include <algorithm>
#include <cmath>


#include "codecs/fmf/fmf.h"
#include "codecs/gpu_export.h"

namespace btfc::gpu {
namespace {

constexpr float k_drr_eps = 1e-5f;
constexpr float k_rgb_from_yuv[3][3] = {{1, 0, 1.13983f}, {1, -0.39465f, -0.5806f}, {1, 2.03211f, 0}};

struct Layout {
  int mode = 0;  // 0: rgb block, linear; 12: rgb block, exp(v) - 1e-5; 11: dfmf y/u/v
  float eps = k_drr_eps;  // mode 11: the model's luminance offset e (Bonn's 1e-5 or from the data)
  int nb = 1;
  int K[3] = {0, 0, 0}, R[3] = {0, 0, 0}, toff[3] = {0, 0, 0}, aoff[3] = {0, 0, 0};
  int tex_layers = 0, abrdf_layers = 0;
};

Layout layout_of(const ExportBundle& b) {
  const nlohmann::json& e = b.evaluation;
  Layout L;
  L.mode = e.at("color_mode").get<int>();
  if (L.mode == 11) L.eps = e.value("luminance_offset", k_drr_eps);  // absent: Bonn's (exports before it was written)
  L.nb = int(e.at("blocks").size());
  for (int i = 0; i < L.nb; ++i) {
    const nlohmann::json& bl = e.at("blocks")[size_t(i)];
    L.K[i] = bl.at("layers").get<int>(), L.R[i] = bl.at("rows_per_direction_pair").get<int>();
    L.toff[i] = bl.at("texture_layer_offset").get<int>(), L.aoff[i] = bl.at("abrdf_layer_offset").get<int>();
  }
  return L;
}

// One factorized value: block b, row r, texel xy, measured (l, v), from stored texels.
// As the shader: dot(texel * CSCALE[layer], abrdf) per layer, summed in layer order.
float block_value(const GpuTexture& T, const GpuTexture& A, const std::vector<float>& cs, const Layout& L, int b, int r, int x, int y,
                  int l, int v) {
  float s = 0;
  for (int j = 0; j < L.K[b]; ++j) {
    const float* t = &T.f[0][((size_t(L.toff[b] + j) * T.height + size_t(y)) * T.width + size_t(x)) * 4];
    const float* a = &A.f[0][((size_t(L.aoff[b] + r * L.K[b] + j) * A.height + size_t(v)) * A.width + size_t(l)) * 4];
    const float* c = &cs[size_t(L.toff[b] + j) * 4];
    s += (t[0] * c[0]) * a[0] + (t[1] * c[1]) * a[1] + (t[2] * c[2]) * a[2] + (t[3] * c[3]) * a[3];
  }
  return s;
}

void measured(const ExportBundle& b, const Layout& L, int x, int y, int l, int v, float* rgb) {
  const GpuTexture& T = *b.find("eigen_texture");
  const GpuTexture& A = *b.find("eigen_abrdf");
  const std::vector<float> cs = b.evaluation.at("component_scale").get<std::vector<float>>();
  rgb[0] = rgb[1] = rgb[2] = 0;
  if (L.mode != 11) {
    for (int c = 0; c < L.R[0] && c < 3; ++c) {
      rgb[c] = block_value(T, A, cs, L, 0, c, x, y, l, v);
      if (L.mode == 12) rgb[c] = std::exp(rgb[c]) - k_drr_eps;
    }
    return;
  }
  const float Y = std::exp(block_value(T, A, cs, L, 0, 0, x, y, l, v)) - L.eps;
  const float yuv[3] = {Y, block_value(T, A, cs, L, 1, 0, x, y, l, v) * (Y + L.eps), block_value(T, A, cs, L, 2, 0, x, y, l, v) * (Y + L.eps)};
  for (int c = 0; c < 3; ++c) rgb[c] = k_rgb_from_yuv[c][0] * yuv[0] + k_rgb_from_yuv[c][1] * yuv[1] + k_rgb_from_yuv[c][2] * yuv[2];
}

void emulate(const ExportBundle& b, const ShaderQuery& q, float* rgb) {
  const Layout L = layout_of(b);
  int x, y;
  const GpuTexture& T = *b.find("eigen_texture");
  uv_texel(q.u, q.v, int(T.width), int(T.height), x, y);
  if (q.light >= 0) return measured(b, L, x, y, q.light, q.view, rgb);
  emulate_delaunay(b, q.wl, q.wv, [&](int l, int v, float* out) { measured(b, L, x, y, l, v, out); }, rgb);
}

std::string shader(const ExportBundle& b, const Layout& L) {
  const auto f = glsl_float;
  std::string s = "#version 300 es\n// btfc fmf reference shader: " + b.spec + "\n" +
                  "// rho(x, l, v) = sum_c U_c(l, v) SxV_c(x) (seed 000 section 4); 9-lookup Delaunay blend.\n"
                  "precision highp float;\nprecision highp int;\n"
                  "uniform highp sampler2DArray u_eigen_texture;\nuniform highp sampler2DArray u_eigen_abrdf;\n"
                  "uniform highp usampler2DArray u_dir_index;\nuniform highp sampler2DArray u_dir_weight;\n";
  s += glsl_common();
  const GpuTexture& T = *b.find("eigen_texture");  // level 0 of the export (a scene may drop finer levels)
  s += "const ivec2 SIZE = ivec2(" + std::to_string(T.width) + ", " + std::to_string(T.height) + ");\n";
  s += "const int DIR_N = " + std::to_string(b.find("dir_index")->width) + ";\n";
  // Per-component scales of the eigen-textures (stored values are SxV / scale, |.| <= 1).
  const std::vector<float> cs = b.evaluation.at("component_scale").get<std::vector<float>>();
  s += "const vec4 CSCALE[" + std::to_string(cs.size() / 4) + "] = vec4[](";
  for (size_t i = 0; i < cs.size(); i += 4)
    s += std::string(i ? ", " : "") + "vec4(" + f(cs[i]) + ", " + f(cs[i + 1]) + ", " + f(cs[i + 2]) + ", " + f(cs[i + 3]) + ")";
  s += ");\n";
  s += "float fmf_block(int toff, int aoff, int K, ivec2 xy, ivec2 lv) {\n"
       "  float s = 0.0;\n"
       "  for (int j = 0; j < K; ++j)\n"
       "    s += dot(texelFetch(u_eigen_texture, ivec3(xy, toff + j), 0) * CSCALE[toff + j], texelFetch(u_eigen_abrdf, ivec3(lv, aoff + j), 0));\n"
       "  return s;\n}\n";
  if (L.mode == 11) s += "const float DFMF_OFFSET = " + f(L.eps) + ";  // e of Y' = log(Y + e), U' = U / (Y + e)\n";
  s += "vec3 fmf_measured(ivec2 xy, int l, int v) {\n  ivec2 lv = ivec2(l, v);\n  vec3 c = vec3(0.0);\n";
  auto blk = [&](int i, int r) {
    return "fmf_block(" + std::to_string(L.toff[i]) + ", " + std::to_string(L.aoff[i] + r * L.K[i]) + ", " + std::to_string(L.K[i]) + ", xy, lv)";
  };
  if (L.mode != 11) {
    for (int c = 0; c < L.R[0] && c < 3; ++c) {
      std::string v = blk(0, c);
      if (L.mode == 12) v = "exp(" + v + ") - " + f(k_drr_eps);
      s += "  c[" + std::to_string(c) + "] = " + v + ";\n";
    }
  } else {
    s += "  float Y = exp(" + blk(0, 0) + ") - DFMF_OFFSET;\n";
    s += "  vec3 yuv = vec3(Y, " + blk(1, 0) + " * (Y + DFMF_OFFSET), " + blk(2, 0) + " * (Y + DFMF_OFFSET));\n";
    for (int c = 0; c < 3; ++c)
      s += "  c[" + std::to_string(c) + "] = " + f(k_rgb_from_yuv[c][0]) + " * yuv.x + " + f(k_rgb_from_yuv[c][1]) + " * yuv.y + " +
           f(k_rgb_from_yuv[c][2]) + " * yuv.z;\n";
  }
  s += "  return c;\n}\n";
  s += "vec3 btf_eval_measured(vec2 uv, int light, int view) {\n  return fmf_measured(btfc_texel(uv, SIZE), light, view);\n}\n";
  s += glsl_delaunay_function("vec3 btf_eval(vec2 uv, vec3 wl, vec3 wv)", "  ivec2 xy = btfc_texel(uv, SIZE);\n",
                              "fmf_measured(xy, int(il[i]), int(iv[j]))");
  s += "#ifndef BTFC_NO_MAIN\nin vec2 v_uv;\nin vec3 v_wl;\nin vec3 v_wv;\nout vec4 btf_color;\n"
       "void main() { btf_color = vec4(btf_eval(v_uv, normalize(v_wl), normalize(v_wv)), 1.0); }\n#endif\n";
  return s;
}

// Bytes of the textures for `K` eigen-texture / `KA` eigen-ABRDF layers, mip levels m0..m1.
uint64_t bytes_for(int K, int KA, const BtfDesc& d, int m0, int m1, size_t nl, size_t nv, int bpc, int dir_n) {
  uint64_t tex = 0;
  for (int m = m0; m <= m1; ++m) tex += uint64_t(std::max(d.width >> m, 1)) * uint64_t(std::max(d.height >> m, 1));
  return (tex * uint64_t(K) + uint64_t(nl) * nv * uint64_t(KA)) * 4 * uint64_t(bpc) + uint64_t(dir_n) * uint64_t(dir_n) * 2 * (8 + 16);
}

// What the scene needs (core/scene.h): mip levels, directions, components.
struct SceneCut {
  int m0 = 0, m1 = 0;
  std::vector<int> ls, vs;
  int C[3] = {0, 0, 0}, Ck[3] = {0, 0, 0};  // components of the model, kept
  uint64_t need = 0;                         // texture bytes of the export
};

SceneCut scene_cut(const FmfFactorsView& fv, const BtfDesc& d, const ExportOptions& opt) {
  SceneCut c;
  const int nb = int(fv.blocks.size());
  int levels = 1;
  while ((d.width >> levels) > 0 || (d.height >> levels) > 0) ++levels;
  c.m1 = levels - 1;
  for (size_t i = 0; i < d.num_lights(); ++i) c.ls.push_back(int(i));
  for (size_t i = 0; i < d.num_views(); ++i) c.vs.push_back(int(i));
  if (opt.scene) {
    scene_mip_range(*opt.scene, c.m0, c.m1);
    c.m0 = std::min(c.m0, levels - 1), c.m1 = std::clamp(c.m1, c.m0, levels - 1);
    c.ls = directions_in_cone(d.lights, opt.scene->light_cone);
    c.vs = directions_in_cone(d.views, opt.scene->view_cone);
  }
  for (int i = 0; i < nb; ++i) c.C[i] = fv.blocks[size_t(i)].C;
  const int bpc = opt.half ? 2 : 4;
  auto layers_for = [&](int q, int* Cq) {  // q eigen-texture layers for block 0, the others in proportion
    int K = 0, KA = 0;
    const int k0 = std::max(1, (c.C[0] + 3) / 4);
    for (int i = 0; i < nb; ++i) {
      const int ki = std::max(1, (c.C[i] + 3) / 4), kq = std::max(1, (q * ki + k0 - 1) / k0);
      Cq[i] = std::min(c.C[i], 4 * kq);
      K += kq, KA += kq * (fv.per_channel ? 1 : d.channels);
    }
    return bytes_for(K, KA, d, c.m0, c.m1, c.ls.size(), c.vs.size(), bpc, opt.direction_map);
  };
  int q = std::max(1, (c.C[0] + 3) / 4);
  c.need = layers_for(q, c.Ck);
  if (opt.scene && opt.scene->gpu_budget)
    while (c.need > opt.scene->gpu_budget && q > 1) c.need = layers_for(--q, c.Ck);
  return c;
}

Result<ExportBundle> build(const Model& model, const ExportOptions& opt) {
  BTFC_ASSIGN_OR_RETURN(FmfFactorsView fv, fmf_factors(model));
  const BtfDesc& d = model.desc();
  Layout L;
  L.mode = fv.per_channel ? 11 : fv.bonn_color_model;
  if ((fv.per_channel && fv.bonn_color_model != 11) || (!fv.per_channel && L.mode != 0 && L.mode != 12))
    return unsupported("export: fmf colour model " + std::to_string(fv.bonn_color_model) + " has no shader (rgb and dfmf only)");
  if (fv.per_channel) L.eps = fv.drr_eps;
  L.nb = int(fv.blocks.size());

  const SceneCut cut = scene_cut(fv, d, opt);
  const int m0 = cut.m0, m1 = cut.m1;
  const std::vector<int>&ls = cut.ls, &vs = cut.vs;
  const int* C = cut.C;
  const int* Ck = cut.Ck;
  const uint64_t need = cut.need;

  for (int i = 0; i < L.nb; ++i) {
    L.K[i] = std::max(1, (Ck[i] + 3) / 4);
    L.R[i] = fv.per_channel ? 1 : d.channels;
    L.toff[i] = L.tex_layers, L.aoff[i] = L.abrdf_layers;
    L.tex_layers += L.K[i], L.abrdf_layers += L.K[i] * L.R[i];
  }
  const size_t W = size_t(d.width), H = size_t(d.height), nl = ls.size(), nv = vs.size();
  std::vector<float> tex(size_t(L.tex_layers) * W * H * 4, 0.f), abrdf(size_t(L.abrdf_layers) * nl * nv * 4, 0.f);
  for (int i = 0; i < L.nb; ++i) {
    const FmfBlockView& bl = fv.blocks[size_t(i)];
    for (size_t t = 0; t < bl.texels; ++t)
      for (int c = 0; c < Ck[i]; ++c) tex[((size_t(L.toff[i] + c / 4) * H * W) + t) * 4 + size_t(c % 4)] = bl.SxV[t * size_t(bl.C) + size_t(c)];
    for (size_t v = 0; v < nv; ++v)
      for (size_t l = 0; l < nl; ++l)
        for (int r = 0; r < L.R[i]; ++r) {
          const size_t ol = size_t(ls[l]), ov = size_t(vs[v]);
          const size_t row = fv.per_channel ? ol + d.num_lights() * ov : size_t(r) + size_t(d.channels) * (ol + d.num_lights() * ov);
          for (int c = 0; c < Ck[i]; ++c)
            abrdf[((size_t(L.aoff[i] + r * L.K[i] + c / 4) * nv + v) * nl + l) * 4 + size_t(c % 4)] = bl.U[row * size_t(bl.C) + size_t(c)];
        }
  }
  // Each eigen-texture component is stored divided by its max |value| (the model's own storage
  // scale: a half model's SxV is half(x / s_c) s_c, so this stores its half values exactly, and
  // no HDR range can overflow half); the scales are shader constants (evaluation.component_scale).
  std::vector<float> cscale(size_t(L.tex_layers) * 4, 1.f);
  for (size_t layer = 0; layer < size_t(L.tex_layers); ++layer)
    for (size_t lane = 0; lane < 4; ++lane) {
      float mx = 0;
      for (size_t t = 0; t < W * H; ++t) mx = std::max(mx, std::fabs(tex[(layer * W * H + t) * 4 + lane]));
      if (mx > 0) cscale[layer * 4 + lane] = mx;
      for (size_t t = 0; t < W * H; ++t) tex[(layer * W * H + t) * 4 + lane] /= cscale[layer * 4 + lane];
    }
  const TexFormat ff = opt.half ? TexFormat::rgba16f : TexFormat::rgba32f;
  ExportBundle b;
  BTFC_ASSIGN_OR_RETURN(GpuTexture T, make_float_texture("eigen_texture", ff, uint32_t(W), uint32_t(H), uint32_t(L.tex_layers), std::move(tex), true));
  if (m0 > 0 || m1 < int(T.num_levels()) - 1) {  // the scene samples only levels m0..m1
    T.f.resize(size_t(m1) + 1);
    T.f.erase(T.f.begin(), T.f.begin() + m0);
    T.width = std::max<uint32_t>(T.width >> m0, 1), T.height = std::max<uint32_t>(T.height >> m0, 1);
  }
  // Mip levels of the eigen-textures are the BTF's own mip levels only when decoding is linear
  // in them (rgb); for log / ratio components (dfmf, colour model 12) they are a filtered model.
  T.meaning = std::string("eigen-textures SxV (V Sigma), 4 components per RGBA texel; value = stored * evaluation.component_scale[4 layer + lane]; mip chain = box-filtered ") +
              (L.mode == 0 ? "BTF (decoding is linear)" : "components (decoding is non-linear: not the BTF's own mip levels)");
  T.channel_meaning = {"component 4j", "component 4j+1", "component 4j+2", "component 4j+3"};
  BTFC_ASSIGN_OR_RETURN(GpuTexture A, make_float_texture("eigen_abrdf", ff, uint32_t(nl), uint32_t(nv), uint32_t(L.abrdf_layers), std::move(abrdf)));
  A.meaning = "eigen-ABRDFs U at (x = light, y = view), layer = abrdf_layer_offset + row * layers + j, 4 components per texel";
  A.channel_meaning = T.channel_meaning;
  BtfDesc dsub = d;  // the kept direction subsets, for the Delaunay maps
  dsub.lights.dirs.clear(), dsub.views.dirs.clear();
  for (int l : ls) dsub.lights.dirs.push_back(d.lights.dirs[size_t(l)]);
  for (int v : vs) dsub.views.dirs.push_back(d.views.dirs[size_t(v)]);
  BTFC_ASSIGN_OR_RETURN(auto dm, direction_maps(dsub, opt.direction_map));
  b.textures.push_back(std::move(T));
  b.textures.push_back(std::move(A));
  b.textures.push_back(std::move(dm.first));
  b.textures.push_back(std::move(dm.second));
  nlohmann::json blocks = nlohmann::json::array();
  for (int i = 0; i < L.nb; ++i)
    blocks.push_back({{"name", fv.blocks[size_t(i)].name},
                      {"components", Ck[i]},
                      {"layers", L.K[i]},
                      {"rows_per_direction_pair", L.R[i]},
                      {"texture_layer_offset", L.toff[i]},
                      {"abrdf_layer_offset", L.aoff[i]}});
  b.evaluation = {{"color_mode", L.mode},
                  {"blocks", blocks},
                  {"formula", "value(b, r) = sum_j dot(eigen_texture[toff_b + j](x, y) * component_scale[toff_b + j], eigen_abrdf[aoff_b + r * layers_b + j](light, view))"},
                  {"component_scale", cscale},
                  {"color", L.mode == 11 ? "dfmf: Y = exp(value(y)) - e; U = value(u) (Y + e); V = value(v) (Y + e); RGB = M YUV; e = luminance_offset"
                            : L.mode == 12 ? "rgb: exp(value(0, c)) - 1e-5" : "rgb: value(0, c)"},
                  {"rgb_from_yuv", {{k_rgb_from_yuv[0][0], k_rgb_from_yuv[0][1], k_rgb_from_yuv[0][2]},
                                    {k_rgb_from_yuv[1][0], k_rgb_from_yuv[1][1], k_rgb_from_yuv[1][2]},
                                    {k_rgb_from_yuv[2][0], k_rgb_from_yuv[2][1], k_rgb_from_yuv[2][2]}}},
                  {"interpolation", "Delaunay in parabolic coordinates p = (x, y) / (1 + z); cell = floor((p / 2 + 1 / 2) n); "
                                    "sum_ij wl_i wv_j value(il_i, iv_j) over dir_index / dir_weight layers 0 (light), 1 (view)"},
                  {"direction_map_size", opt.direction_map},
                  {"light_indices", ls},
                  {"view_indices", vs},
                  {"first_mip_level", m0}};
  if (L.mode == 11) b.evaluation["luminance_offset"] = L.eps;
  if (opt.scene) {
    // Eckart-Young: the dropped components' share of the model's energy is the added relative L2.
    nlohmann::json err = nlohmann::json::object();
    double worst = 0;
    for (int i = 0; i < L.nb; ++i) {
      double all = 0, dropped = 0;
      for (int c = 0; c < C[i]; ++c) {
        const double s2 = double(fv.blocks[size_t(i)].S[c]) * fv.blocks[size_t(i)].S[c];
        all += s2, dropped += c >= Ck[i] ? s2 : 0;
      }
      const double e = all > 0 ? std::sqrt(dropped / all) : 0;
      err[fv.blocks[size_t(i)].name] = e;
      worst = std::max(worst, e);
    }
    b.scene_report = {{"mip_levels", {m0, m1}},
                      {"texture_size", {b.textures[0].width, b.textures[0].height}},
                      {"lights_kept", ls.size()},
                      {"views_kept", vs.size()},
                      {"components_kept", std::vector<int>(Ck, Ck + L.nb)},
                      {"components_model", std::vector<int>(C, C + L.nb)},
                      {"predicted_added_rel_error_per_block", err},
                      {"predicted_added_rel_error", worst},
                      {"predicted_bytes", need}};
  }
  b.desc = d, b.spec = model.spec();
  b.glsl = shader(b, L);
  return b;
}

}  // namespace

Result<std::unique_ptr<Model>> fmf_scene_model(const Model& model, const ExportOptions& opt) {
  BTFC_ASSIGN_OR_RETURN(FmfFactorsView fv, fmf_factors(model));
  const BtfDesc& d = model.desc();
  if ((fv.per_channel && fv.bonn_color_model != 11) || (!fv.per_channel && fv.bonn_color_model != 0 && fv.bonn_color_model != 12))
    return unsupported("export: fmf colour model " + std::to_string(fv.bonn_color_model) + " has no scene model (rgb and dfmf only)");
  const SceneCut cut = scene_cut(fv, d, opt);
  BtfDesc sd = d;
  sd.lights.dirs.clear(), sd.views.dirs.clear();
  for (int l : cut.ls) sd.lights.dirs.push_back(d.lights.dirs[size_t(l)]);
  for (int v : cut.vs) sd.views.dirs.push_back(d.views.dirs[size_t(v)]);
  sd.lights.identify(), sd.views.identify();
  std::vector<FmfFactors> blocks;
  for (size_t i = 0; i < fv.blocks.size(); ++i) {
    const FmfBlockView& bl = fv.blocks[i];
    const int C = cut.Ck[i];
    FmfFactors f;
    f.name = bl.name, f.C = C;
    f.S.assign(bl.S, bl.S + C);
    // Eigen-textures box-filtered to level m0 (the texture's own mip chain, in float).
    std::vector<float> layers(size_t(C) * bl.texels);
    for (int c = 0; c < C; ++c)
      for (size_t t = 0; t < bl.texels; ++t) layers[size_t(c) * bl.texels + t] = bl.SxV[t * size_t(bl.C) + size_t(c)];
    BTFC_ASSIGN_OR_RETURN(GpuTexture tex, make_float_texture("sxv", TexFormat::r32f, uint32_t(d.width), uint32_t(d.height), uint32_t(C),
                                                             std::move(layers), cut.m0 > 0));
    const size_t n = size_t(tex.level_width(uint32_t(cut.m0))) * tex.level_height(uint32_t(cut.m0));
    f.SxV.resize(n * size_t(C));
    for (size_t t = 0; t < n; ++t)
      for (int c = 0; c < C; ++c) f.SxV[t * size_t(C) + size_t(c)] = tex.f[size_t(cut.m0)][size_t(c) * n + t];
    const size_t rpd = fv.per_channel ? 1 : size_t(d.channels);
    for (int v : cut.vs)
      for (int l : cut.ls)
        for (size_t r = 0; r < rpd; ++r) {
          const size_t row = r + rpd * (size_t(l) + d.num_lights() * size_t(v));
          f.U.insert(f.U.end(), bl.U + row * size_t(bl.C), bl.U + row * size_t(bl.C) + C);
        }
    blocks.push_back(std::move(f));
  }
  sd.width = int(std::max(1, d.width >> cut.m0)), sd.height = int(std::max(1, d.height >> cut.m0));
  return make_fmf_model(sd, fv.bonn_color_model, std::move(blocks), fv.color_mean, fv.color_transform, fv.half, fv.drr_eps);
}

const Exporter k_fmf_exporter = {"fmf", &build, &emulate};

}  // namespace btfc::gpu
