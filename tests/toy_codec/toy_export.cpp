// Codec `toy`'s GPU exporter (tests/toy_codec/toy.h): textures, reference shader, CPU emulation.
//   mean        2D nL x nV RGBA32F: texel (l, v) = (mean R, G, B, 0) at light l, view v
//   gain        2D W x H R32F: the texel's gain
//   dir_index / dir_weight   the shared parabolic Delaunay maps (codecs/gpu_export.h)
#include <algorithm>
#include <string>

#include "codecs/gpu_export.h"
#include "tests/toy_codec/toy.h"

namespace btfc::gpu {
namespace {

Result<ExportBundle> build(const Model& model, const ExportOptions& opt) {
  const BtfDesc& d = model.desc();
  BTFC_ASSIGN_OR_RETURN(std::vector<Tensor> ts, model.gpu_tensors());
  const Tensor* tm = nullptr;
  const Tensor* tg = nullptr;
  for (const Tensor& t : ts) {
    if (t.name == "mean") tm = &t;
    if (t.name == "gain") tg = &t;
  }
  if (!tm || !tg) return corrupt_data(model.spec() + ": toy model without mean / gain tensors");
  BTFC_ASSIGN_OR_RETURN(std::vector<float> mean, tm->to_f32());
  BTFC_ASSIGN_OR_RETURN(std::vector<float> gain, tg->to_f32());
  const size_t nl = d.num_lights(), nv = d.num_views();
  std::vector<float> rgba(nl * nv * 4, 0.0f);
  for (size_t v = 0; v < nv; ++v)
    for (size_t l = 0; l < nl; ++l)
      for (int c = 0; c < std::min(d.channels, 3); ++c) rgba[(v * nl + l) * 4 + size_t(c)] = mean[d.row(l, v, size_t(c))];
  ExportBundle b;
  BTFC_ASSIGN_OR_RETURN(GpuTexture M, make_float_texture("mean", TexFormat::rgba32f, uint32_t(nl), uint32_t(nv), 0, std::move(rgba)));
  M.meaning = "mean ABRDF: texel (l, v) = RGB at light l, view v";
  M.channel_meaning = {"R", "G", "B", "unused"};
  BTFC_ASSIGN_OR_RETURN(GpuTexture G, make_float_texture("gain", TexFormat::r32f, uint32_t(d.width), uint32_t(d.height), 0, std::move(gain)));
  G.meaning = "per-texel gain";
  G.channel_meaning = {"gain"};
  b.textures.push_back(std::move(M));
  b.textures.push_back(std::move(G));
  BTFC_ASSIGN_OR_RETURN(auto dm, direction_maps(d, opt.direction_map));
  b.textures.push_back(std::move(dm.first));
  b.textures.push_back(std::move(dm.second));
  b.evaluation = {{"formula", "rgb(x, y, l, v) = gain(x, y) * mean(l, v).rgb"}, {"direction_map_size", opt.direction_map}};
  b.desc = d, b.spec = model.spec();
  b.glsl = "#version 300 es\n// btfc toy reference shader: " + b.spec +
           "\nprecision highp float;\nprecision highp int;\n"
           "uniform highp sampler2D u_mean;\nuniform highp sampler2D u_gain;\n"
           "uniform highp usampler2DArray u_dir_index;\nuniform highp sampler2DArray u_dir_weight;\n";
  b.glsl += glsl_common();
  b.glsl += "const ivec2 SIZE = ivec2(" + std::to_string(d.width) + ", " + std::to_string(d.height) + ");\nconst int DIR_N = " +
            std::to_string(opt.direction_map) + ";\n";
  b.glsl += "vec3 btf_eval_measured(vec2 uv, int light, int view) {\n"
            "  return texelFetch(u_gain, btfc_texel(uv, SIZE), 0).r * texelFetch(u_mean, ivec2(light, view), 0).rgb;\n}\n";
  b.glsl += glsl_delaunay_function("vec3 btf_eval(vec2 uv, vec3 wl, vec3 wv)", "", "btf_eval_measured(uv, int(il[i]), int(iv[j]))");
  b.glsl += "#ifndef BTFC_NO_MAIN\nin vec2 v_uv;\nin vec3 v_wl;\nin vec3 v_wv;\nout vec4 btf_color;\n"
            "void main() { btf_color = vec4(btf_eval(v_uv, normalize(v_wl), normalize(v_wv)), 1.0); }\n#endif\n";
  return b;
}

void emulate(const ExportBundle& b, const ShaderQuery& q, float* rgb) {
  const GpuTexture* M = b.find("mean");
  const GpuTexture* G = b.find("gain");
  int x, y;
  uv_texel(q.u, q.v, b.desc.width, b.desc.height, x, y);
  const float g = G->f[0][size_t(y) * G->width + size_t(x)];
  auto measured = [&](int l, int v, float* out) {
    for (int c = 0; c < 3; ++c) out[c] = g * M->f[0][(size_t(v) * M->width + size_t(l)) * 4 + size_t(c)];
  };
  if (q.light >= 0) return measured(q.light, q.view, rgb);
  emulate_delaunay(b, q.wl, q.wv, measured, rgb);
}

}  // namespace

const Exporter k_toy_exporter = {"toy", &build, &emulate};

}  // namespace btfc::gpu
