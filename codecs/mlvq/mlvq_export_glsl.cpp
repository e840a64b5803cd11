// mlvq reference shader (GLSL ES 3.00, contract in codecs/gpu_export.h) and its CPU emulation.
// The two are kept side by side and mirror each other statement by statement: the emulation
// reads only the bundle's stored texel values, in the shader's float arithmetic, so a test that
// compares it with the model checks the textures and the formula, and a GL run that compares the
// GPU with it checks the GLSL. Both mirror the model's eval_stencil / node_lrg / grid_coord
// (codecs/mlvq/mlvq_model.cpp, resample.cpp); the only difference to the model is that grid
// coordinates of arbitrary directions are computed in float (the model uses double).
#include <algorithm>
#include <cmath>
#include <cstdio>

#include "codecs/mlvq/mlvq_export.h"

namespace btfc::gpu::mlvq_export {
namespace {

constexpr float k_pi = 3.14159265358979f;
constexpr const char* k_parts[3] = {"rgb", "lum", "chroma"};
constexpr const char* k_swizzle = "xyzw";  // ivec4 node coordinate: level k at component k - 1

const auto num = glsl_float;

// ---- emulation side ----------------------------------------------------------------------------

struct View {
  int scheme = 2, channels = 3, n[5] = {0, 0, 0, 0, 0};
  bool measured = false;  // layout measured: directions by the Delaunay maps (export.h)
  const GpuTexture *texel_index = nullptr, *texel_scale = nullptr, *merge = nullptr, *lum1 = nullptr, *chroma1 = nullptr,
                   *measured_coord = nullptr;
  const GpuTexture* index[3][5] = {};
  const GpuTexture* scale[3][5] = {};
};

View view_of(const ExportBundle& b) {
  const nlohmann::json& e = b.evaluation;
  View v;
  v.scheme = e.at("scheme").get<int>();
  v.channels = e.at("channels").get<int>();
  const nlohmann::json& g = e.at("grid");
  v.n[1] = g.at("nbeta").get<int>(), v.n[2] = g.at("nalpha").get<int>(), v.n[3] = g.at("ntheta").get<int>(), v.n[4] = g.at("nphi").get<int>();
  v.measured = e.contains("layout") && e.at("layout") == "measured";
  v.texel_index = b.find("texel_index"), v.texel_scale = b.find("texel_scale"), v.merge = b.find("merge");
  v.lum1 = b.find("lum1"), v.chroma1 = b.find("chroma1"), v.measured_coord = b.find("measured_coord");
  for (int k = 2; k <= 4; ++k)
    for (int p = 0; p < 3; ++p) {
      v.index[p][k] = b.find(book_texture(k_parts[p], k, "index"));
      v.scale[p][k] = b.find(book_texture(k_parts[p], k, "scale"));
    }
  return v;
}

// texelFetch(s, ivec2(i % w, i / w), 0) of a 1D-array texture (mlvq_u / mlvq_f in the shader).
uint32_t fetch_u(const GpuTexture& t, int i, int c = 0) {
  const int w = int(t.width), ch = format_info(t.format).channels;
  return t.u[0][(size_t(i / w) * t.width + size_t(i % w)) * size_t(ch) + size_t(c)];
}
float fetch_f(const GpuTexture& t, int i, int c = 0) {
  const int w = int(t.width), ch = format_info(t.format).channels;
  return t.f[0][(size_t(i / w) * t.width + size_t(i % w)) * size_t(ch) + size_t(c)];
}

// mlvq_axis
void axis(float v, int n, bool periodic, int i[2], float w[2]) {
  if (n == 1) {
    i[0] = i[1] = 0, w[0] = 1, w[1] = 0;
    return;
  }
  const float f = std::floor(v);
  int i0 = int(f);
  float t = v - f;
  if (periodic) {
    if (i0 < 0) i0 += n;
    if (i0 >= n) i0 -= n;
    i[0] = i0, i[1] = i0 + 1 == n ? 0 : i0 + 1;
  } else {
    if (i0 >= n - 1) i0 = n - 2, t = 1;
    if (i0 < 0) i0 = 0, t = 0;
    i[0] = i0, i[1] = i0 + 1;
  }
  w[0] = 1 - t, w[1] = t;
}

// mlvq_grid_coord: (phi, theta, alpha, beta) in node units. The model's grid_coord in float, with
// theta = atan2(|wv.xy|, wv.z) and (cos, sin) phi_v = wv.xy / |wv.xy| (equal for unit vectors).
void grid_coord(const View& V, const Vec3& wl, const Vec3& wv, float c[4]) {
  const float r = std::sqrt(wv.x * wv.x + wv.y * wv.y);
  const float tv = std::atan2(r, wv.z);
  float pv = r == 0 ? 0.f : std::atan2(wv.y, wv.x);
  if (pv < 0) pv += 2 * k_pi;
  c[1] = V.n[3] > 1 ? std::clamp(tv / (0.5f * k_pi) * float(V.n[3] - 1), 0.f, float(V.n[3] - 1)) : 0.f;
  c[0] = pv / (2 * k_pi) * float(V.n[4]);
  if (!(c[0] < float(V.n[4]))) c[0] = 0;
  const float cp = r == 0 ? 1.f : wv.x / r, sp = r == 0 ? 0.f : wv.y / r;
  const float lx = cp * wl.x + sp * wl.y, ly = -sp * wl.x + cp * wl.y, lz = std::max(0.f, wl.z);
  const float len = std::sqrt(lx * lx + ly * ly + lz * lz);
  const float a = lx == 0 && lz == 0 ? 0.f : std::atan2(lx, lz);
  const float sb = len > 0 ? std::clamp(ly / len, -1.f, 1.f) : 0.f;
  c[2] = V.n[2] > 1 ? std::clamp((a + 0.5f * k_pi) / k_pi * float(V.n[2] - 1), 0.f, float(V.n[2] - 1)) : 0.f;
  c[3] = V.n[1] > 1 ? std::clamp((sb + 1) * 0.5f * float(V.n[1] - 1), 0.f, float(V.n[1] - 1)) : 0.f;
}

// mlvq_node: the chained lookups of one grid node (cd[k - 1] = node index on level k's axis).
void node(const View& V, int e, float sc, const int cd[4], float rgb[3]) {
  int o;
  for (int k = 4; k > V.scheme; --k) {
    o = e * V.n[k] + cd[k - 1];
    sc *= fetch_f(*V.scale[0][k], o) * float(V.scale[0][k]->scale);
    e = int(fetch_u(*V.index[0][k], o));
  }
  int li = int(fetch_u(*V.merge, e, 0)), ci = int(fetch_u(*V.merge, e, 1));
  for (int k = V.scheme; k > 1; --k) {
    o = li * V.n[k] + cd[k - 1];
    sc *= fetch_f(*V.scale[1][k], o) * float(V.scale[1][k]->scale);
    li = int(fetch_u(*V.index[1][k], o));
    ci = int(fetch_u(*V.index[2][k], ci * V.n[k] + cd[k - 1]));
  }
  const float L = sc * (fetch_f(*V.lum1, li * V.n[1] + cd[0]) * float(V.lum1->scale));
  const float r = fetch_f(*V.chroma1, ci * V.n[1] + cd[0], 0) * float(V.chroma1->scale);
  const float g = fetch_f(*V.chroma1, ci * V.n[1] + cd[0], 1) * float(V.chroma1->scale);
  const float s3 = 3.f * L;
  rgb[0] = s3 * r, rgb[1] = s3 * g, rgb[2] = s3 * (1.f - r - g);
}

// mlvq_eval
void eval(const View& V, int x, int y, const float c[4], float out[3]) {
  int ib[2], ia[2], it[2], ip[2];
  float wb[2], wa[2], wt[2], wp[2];
  axis(c[3], V.n[1], false, ib, wb);
  axis(c[2], V.n[2], false, ia, wa);
  axis(c[1], V.n[3], false, it, wt);
  axis(c[0], V.n[4], true, ip, wp);
  const size_t t = size_t(y) * V.texel_index->width + size_t(x);
  const int e = int(V.texel_index->u[0][t]);
  const float sc = V.texel_scale->f[0][t] * float(V.texel_scale->scale);
  float acc[3] = {0, 0, 0}, v[3];
  for (int m = 0; m < 16; ++m) {
    const int b0 = m & 1, b1 = (m >> 1) & 1, b2 = (m >> 2) & 1, b3 = (m >> 3) & 1;
    const float w = wb[b0] * wa[b1] * wt[b2] * wp[b3];
    if (w == 0) continue;
    const int cd[4] = {ib[b0], ia[b1], it[b2], ip[b3]};
    node(V, e, sc, cd, v);
    for (int ch = 0; ch < 3; ++ch) acc[ch] += w * v[ch];
  }
  for (int ch = 0; ch < 3; ++ch) out[ch] = acc[ch];
}

}  // namespace

void emulate(const ExportBundle& b, const ShaderQuery& q, float* rgb) {
  const View V = view_of(b);
  int x, y;
  uv_texel(q.u, q.v, b.desc.width, b.desc.height, x, y);
  float c[4];
  const GpuTexture& M = *V.measured_coord;
  auto at_measured = [&](int l, int v, float* out) {
    float cc[4];
    for (int i = 0; i < 4; ++i) cc[i] = M.f[0][(size_t(v) * M.width + size_t(l)) * 4 + size_t(i)];
    eval(V, x, y, cc, out);
  };
  if (q.light >= 0) {
    for (int i = 0; i < 4; ++i) c[i] = M.f[0][(size_t(q.view) * M.width + size_t(q.light)) * 4 + size_t(i)];
  } else if (V.measured) {
    emulate_delaunay(b, q.wl, q.wv, at_measured, rgb);
    if (V.channels == 1) rgb[1] = rgb[2] = 0;
    return;
  } else {
    grid_coord(V, q.wl, q.wv, c);
  }
  eval(V, x, y, c, rgb);
  if (V.channels == 1) rgb[1] = rgb[2] = 0;
}

// ---- shader side ---------------------------------------------------------------------------------

std::string shader(const ExportBundle& b) {
  const View V = view_of(b);
  std::string s = "#version 300 es\n// btfc mlvq reference shader: " + b.spec + "\n" +
                  "// Multi-level VQ (seed 003 section 3): chained codebook lookups at the 16 nodes of the 4D grid\n"
                  "// (phi_v, theta_v, alpha, beta) around the query, blended multilinearly; colour split at level " +
                  std::to_string(V.scheme) + ".\nprecision highp float;\nprecision highp int;\n";
  for (const GpuTexture& t : b.textures)
    s += std::string("uniform highp ") + (t.is_integer() ? "usampler2D" : "sampler2D") + (t.layers ? "Array" : "") + " u_" + t.name + ";\n";
  s += glsl_common();
  s += "const ivec2 SIZE = ivec2(" + std::to_string(b.desc.width) + ", " + std::to_string(b.desc.height) + ");\n";
  s += "const int NPHI = " + std::to_string(V.n[4]) + ", NTHETA = " + std::to_string(V.n[3]) + ", NALPHA = " + std::to_string(V.n[2]) +
       ", NBETA = " + std::to_string(V.n[1]) + ";\n";
  s += "const float PI = 3.14159265358979;\n";
  if (V.measured) s += "const int DIR_N = " + std::to_string(b.find("dir_index")->width) + ";\n";
  for (const GpuTexture& t : b.textures)
    if (!t.is_integer()) s += "const float S_" + t.name + " = " + num(t.scale) + ";\n";
  s += R"(// Entry i of a 1D array stored in rows of textureSize().x texels.
uint mlvq_u(highp usampler2D s, int i) { int w = textureSize(s, 0).x; return texelFetch(s, ivec2(i % w, i / w), 0).r; }
uvec2 mlvq_u2(highp usampler2D s, int i) { int w = textureSize(s, 0).x; return texelFetch(s, ivec2(i % w, i / w), 0).rg; }
float mlvq_f(highp sampler2D s, int i) { int w = textureSize(s, 0).x; return texelFetch(s, ivec2(i % w, i / w), 0).r; }
vec2 mlvq_f2(highp sampler2D s, int i) { int w = textureSize(s, 0).x; return texelFetch(s, ivec2(i % w, i / w), 0).rg; }
// Two nodes and weights of one axis (phi periodic, the others clamped).
void mlvq_axis(float v, int n, bool periodic, out ivec2 i, out vec2 w) {
  if (n == 1) { i = ivec2(0); w = vec2(1.0, 0.0); return; }
  float f = floor(v);
  int i0 = int(f);
  float t = v - f;
  if (periodic) {
    if (i0 < 0) i0 += n;
    if (i0 >= n) i0 -= n;
    i = ivec2(i0, i0 + 1 == n ? 0 : i0 + 1);
  } else {
    if (i0 >= n - 1) { i0 = n - 2; t = 1.0; }
    if (i0 < 0) { i0 = 0; t = 0.0; }
    i = ivec2(i0, i0 + 1);
  }
  w = vec2(1.0 - t, t);
}
// Grid coordinates (phi, theta, alpha, beta) in node units of a light / view pair. theta from atan
// (not acos) and the azimuth rotation from wv.xy / |wv.xy| (not cos / sin of phi): GPUs' acos, sin
// and cos are coarse approximations (llvmpipe: ~1e-4 rad), their atan is accurate to ~1e-6.
vec4 mlvq_grid_coord(vec3 wl, vec3 wv) {
  float r = sqrt(wv.x * wv.x + wv.y * wv.y);
  float tv = atan(r, wv.z);
  float pv = r == 0.0 ? 0.0 : atan(wv.y, wv.x);
  if (pv < 0.0) pv += 2.0 * PI;
  vec4 c;
  c.y = NTHETA > 1 ? clamp(tv / (0.5 * PI) * float(NTHETA - 1), 0.0, float(NTHETA - 1)) : 0.0;
  c.x = pv / (2.0 * PI) * float(NPHI);
  if (!(c.x < float(NPHI))) c.x = 0.0;
  float cp = r == 0.0 ? 1.0 : wv.x / r, sp = r == 0.0 ? 0.0 : wv.y / r;
  float lx = cp * wl.x + sp * wl.y, ly = -sp * wl.x + cp * wl.y, lz = max(0.0, wl.z);
  float len = sqrt(lx * lx + ly * ly + lz * lz);
  float a = (lx == 0.0 && lz == 0.0) ? 0.0 : atan(lx, lz);
  float sb = len > 0.0 ? clamp(ly / len, -1.0, 1.0) : 0.0;
  c.z = NALPHA > 1 ? clamp((a + 0.5 * PI) / PI * float(NALPHA - 1), 0.0, float(NALPHA - 1)) : 0.0;
  c.w = NBETA > 1 ? clamp((sb + 1.0) * 0.5 * float(NBETA - 1), 0.0, float(NBETA - 1)) : 0.0;
  return c;
}
)";
  // The node chain, unrolled for this model's scheme.
  const char* nname[5] = {"", "NBETA", "NALPHA", "NTHETA", "NPHI"};
  s += "// RGB of grid node cd (cd.x beta, .y alpha, .z theta, .w phi) of a texel with 4D entry e, scale sc.\n"
       "vec3 mlvq_node(int e, float sc, ivec4 cd) {\n  int o;\n";
  for (int k = 4; k > V.scheme; --k) {
    const std::string ix = book_texture("rgb", k, "index"), sx = book_texture("rgb", k, "scale");
    s += "  o = e * " + std::string(nname[k]) + " + cd." + k_swizzle[k - 1] + ";\n";
    s += "  sc *= mlvq_f(u_" + sx + ", o) * S_" + sx + ";\n";
    s += "  e = int(mlvq_u(u_" + ix + ", o));\n";
  }
  s += "  uvec2 mg = mlvq_u2(u_merge, e);\n  int li = int(mg.x), ci = int(mg.y);\n";
  for (int k = V.scheme; k > 1; --k) {
    const std::string lx = book_texture("lum", k, "index"), ls = book_texture("lum", k, "scale"), cx = book_texture("chroma", k, "index");
    const std::string c = std::string("cd.") + k_swizzle[k - 1];
    s += "  o = li * " + std::string(nname[k]) + " + " + c + ";\n";
    s += "  sc *= mlvq_f(u_" + ls + ", o) * S_" + ls + ";\n";
    s += "  li = int(mlvq_u(u_" + lx + ", o));\n";
    s += "  ci = int(mlvq_u(u_" + cx + ", ci * " + nname[k] + " + " + c + "));\n";
  }
  s += R"(  float L = sc * (mlvq_f(u_lum1, li * NBETA + cd.x) * S_lum1);
  vec2 rg = mlvq_f2(u_chroma1, ci * NBETA + cd.x) * S_chroma1;
  float s3 = 3.0 * L;
  return vec3(s3 * rg.x, s3 * rg.y, s3 * (1.0 - rg.x - rg.y));
}
// The 4D multilinear blend of the 16 surrounding nodes.
vec3 mlvq_eval(ivec2 xy, vec4 c) {
  ivec2 ib, ia, it, ip;
  vec2 wb, wa, wt, wp;
  mlvq_axis(c.w, NBETA, false, ib, wb);
  mlvq_axis(c.z, NALPHA, false, ia, wa);
  mlvq_axis(c.y, NTHETA, false, it, wt);
  mlvq_axis(c.x, NPHI, true, ip, wp);
  int e = int(texelFetch(u_texel_index, xy, 0).r);
  float sc = texelFetch(u_texel_scale, xy, 0).r * S_texel_scale;
  vec3 acc = vec3(0.0);
  for (int m = 0; m < 16; ++m) {
    int b0 = m & 1, b1 = (m >> 1) & 1, b2 = (m >> 2) & 1, b3 = (m >> 3) & 1;
    float w = wb[b0] * wa[b1] * wt[b2] * wp[b3];
    if (w == 0.0) continue;
    acc += w * mlvq_node(e, sc, ivec4(ib[b0], ia[b1], it[b2], ip[b3]));
  }
  return acc;
}
)";
  const std::string ret = V.channels == 1 ? "vec3(r.x, 0.0, 0.0)" : "r";
  s += "vec3 btf_eval_measured(vec2 uv, int light, int view) {\n"
       "  vec3 r = mlvq_eval(btfc_texel(uv, SIZE), texelFetch(u_measured_coord, ivec2(light, view), 0));\n"
       "  return " + ret + ";\n}\n";
  if (V.measured) {
    s += glsl_delaunay_function("vec3 mlvq_eval_dir(ivec2 xy, vec3 wl, vec3 wv)", "",
                                "mlvq_eval(xy, texelFetch(u_measured_coord, ivec2(int(il[i]), int(iv[j])), 0))");
    s += "vec3 btf_eval(vec2 uv, vec3 wl, vec3 wv) {\n"
         "  vec3 r = mlvq_eval_dir(btfc_texel(uv, SIZE), wl, wv);\n"
         "  return " + ret + ";\n}\n";
  } else {
    s += "vec3 btf_eval(vec2 uv, vec3 wl, vec3 wv) {\n"
         "  vec3 r = mlvq_eval(btfc_texel(uv, SIZE), mlvq_grid_coord(wl, wv));\n"
         "  return " + ret + ";\n}\n";
  }
  s += "#ifndef BTFC_NO_MAIN\nin vec2 v_uv;\nin vec3 v_wl;\nin vec3 v_wv;\nout vec4 btf_color;\n"
       "void main() { btf_color = vec4(btf_eval(v_uv, normalize(v_wl), normalize(v_wv)), 1.0); }\n#endif\n";
  return s;
}

}  // namespace btfc::gpu::mlvq_export
