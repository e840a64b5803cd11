#include "tests/gl/egl_runner.h"

#include <EGL/egl.h>
#include <EGL/eglext.h>
#include <GLES3/gl32.h>

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "formats/gpu/ktx2.h"

namespace btfc::gltest {
namespace {

std::string hex(unsigned v) {
  char s[16];
  std::snprintf(s, sizeof s, "0x%04X", v);
  return s;
}

struct Egl {
  EGLDisplay dpy = EGL_NO_DISPLAY;
  EGLContext ctx = EGL_NO_CONTEXT;
  Status status;
};

// EGL / GL failures are device errors (the GPU API, not the export, failed).
Status device_error(std::string m) { return {StatusCode::device_error, std::move(m)}; }

Status egl_fail(const std::string& what) { return device_error("EGL: " + what + " failed (eglGetError " + hex(unsigned(eglGetError())) + ")"); }

Egl make_egl() {
  Egl e;
  // Client extensions: the surfaceless platform needs no X server, window or GPU device.
  const char* client = eglQueryString(EGL_NO_DISPLAY, EGL_EXTENSIONS);
  if (!client || !std::strstr(client, "EGL_MESA_platform_surfaceless")) {
    e.status = device_error(std::string("EGL: no EGL_MESA_platform_surfaceless client extension (is libegl-mesa0 installed?); client extensions: ") +
                           (client && *client ? client : "none"));
    return e;
  }
  auto get_display = reinterpret_cast<PFNEGLGETPLATFORMDISPLAYEXTPROC>(eglGetProcAddress("eglGetPlatformDisplayEXT"));
  if (!get_display) return e.status = device_error("EGL: eglGetPlatformDisplayEXT not found"), e;
  e.dpy = get_display(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, nullptr);
  EGLint major = 0, minor = 0;
  if (e.dpy == EGL_NO_DISPLAY) return e.status = egl_fail("eglGetPlatformDisplayEXT(EGL_PLATFORM_SURFACELESS_MESA)"), e;
  if (!eglInitialize(e.dpy, &major, &minor)) return e.status = egl_fail("eglInitialize (is libgl1-mesa-dri installed?)"), e;
  if (!eglBindAPI(EGL_OPENGL_ES_API)) return e.status = egl_fail("eglBindAPI(EGL_OPENGL_ES_API)"), e;
  const char* dext = eglQueryString(e.dpy, EGL_EXTENSIONS);
  if (!dext || !std::strstr(dext, "EGL_KHR_surfaceless_context"))
    return e.status = device_error("EGL: display lacks EGL_KHR_surfaceless_context"), e;
  // Any ES3 config will do (we render into a framebuffer object); none: a config-less context.
  const EGLint cfg_attr[] = {EGL_RENDERABLE_TYPE, EGL_OPENGL_ES3_BIT, EGL_NONE};
  EGLConfig cfg = nullptr;
  EGLint ncfg = 0;
  if (!eglChooseConfig(e.dpy, cfg_attr, &cfg, 1, &ncfg) || ncfg < 1) {
    if (!std::strstr(dext, "EGL_KHR_no_config_context")) return e.status = egl_fail("eglChooseConfig (ES3)"), e;
    cfg = EGL_NO_CONFIG_KHR;
  }
  for (EGLint want_minor : {2, 0}) {
    const EGLint ctx_attr[] = {EGL_CONTEXT_MAJOR_VERSION, 3, EGL_CONTEXT_MINOR_VERSION, want_minor, EGL_NONE};
    e.ctx = eglCreateContext(e.dpy, cfg, EGL_NO_CONTEXT, ctx_attr);
    if (e.ctx != EGL_NO_CONTEXT) break;
  }
  if (e.ctx == EGL_NO_CONTEXT) return e.status = egl_fail("eglCreateContext (GLES 3.2 and 3.0)"), e;
  if (!eglMakeCurrent(e.dpy, EGL_NO_SURFACE, EGL_NO_SURFACE, e.ctx)) return e.status = egl_fail("eglMakeCurrent (surfaceless)"), e;
  return e;
}

const Egl& egl() {
  static const Egl e = make_egl();
  return e;
}

// GL object names released on scope exit (the harness may fail half way).
struct GlObjects {
  std::vector<GLuint> textures, shaders;
  GLuint program = 0, fbo = 0, vao = 0;
  ~GlObjects() {
    if (!textures.empty()) glDeleteTextures(GLsizei(textures.size()), textures.data());
    for (GLuint s : shaders) glDeleteShader(s);
    if (program) glDeleteProgram(program);
    if (fbo) glDeleteFramebuffers(1, &fbo);
    if (vao) glDeleteVertexArrays(1, &vao);
  }
};

Status gl_error(const std::string& what) {
  const GLenum e = glGetError();
  if (e == GL_NO_ERROR) return {};
  return device_error("GL: " + what + ": glGetError " + hex(e));
}

Result<GLuint> compile(GlObjects& o, GLenum stage, const std::string& src, const std::string& what) {
  const GLuint s = glCreateShader(stage);
  o.shaders.push_back(s);
  const char* p = src.c_str();
  glShaderSource(s, 1, &p, nullptr);
  glCompileShader(s);
  GLint ok = 0, len = 0;
  glGetShaderiv(s, GL_COMPILE_STATUS, &ok);
  glGetShaderiv(s, GL_INFO_LOG_LENGTH, &len);
  std::string log(size_t(std::max(len, 1)), '\0');
  glGetShaderInfoLog(s, len, nullptr, log.data());
  if (!ok) return invalid_argument(what + ": GLSL compile failed:\n" + log.c_str());
  return s;
}

// Fragment source = btf.frag with BTFC_NO_MAIN defined + the query-reading main().
Result<std::string> harness_fragment(const std::string& frag, const std::string& path) {
  const size_t eol = frag.find('\n');
  if (frag.rfind("#version 300 es", 0) != 0 || eol == std::string::npos)
    return invalid_argument(path + ": the first line must be '#version 300 es' (shader contract, codecs/gpu_export.h)");
  return frag.substr(0, eol + 1) + "#define BTFC_NO_MAIN\n" + frag.substr(eol + 1) +
         R"(
// ---- tests/gl/egl_runner.cpp harness ----
precision highp float;
precision highp int;
uniform highp sampler2D btfc_harness_q0;
uniform highp sampler2D btfc_harness_q1;
uniform highp sampler2D btfc_harness_q2;
layout(location = 0) out vec4 btfc_harness_out;
void main() {
  ivec2 p = ivec2(gl_FragCoord.xy);
  vec4 a = texelFetch(btfc_harness_q0, p, 0);
  vec3 c;
  if (a.z >= 0.0) c = btf_eval_measured(a.xy, int(a.z), int(a.w));
  else c = btf_eval(a.xy, texelFetch(btfc_harness_q1, p, 0).xyz, texelFetch(btfc_harness_q2, p, 0).xyz);
  btfc_harness_out = vec4(c, 1.0);
}
)";
}

// A full-screen triangle from gl_VertexID (no vertex buffers).
const char* k_vertex = R"(#version 300 es
void main() {
  vec2 p = vec2(float((gl_VertexID << 1) & 2), float(gl_VertexID & 2));
  gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0);
}
)";

struct ManifestTexture {
  std::string name, sampler, file, filter;
  gpu::GpuTexture tex;
};

Result<std::vector<ManifestTexture>> load_textures(const nlohmann::json& m, const std::filesystem::path& dir) {
  std::vector<ManifestTexture> out;
  try {
    for (const nlohmann::json& j : m.at("textures")) {
      ManifestTexture t;
      t.name = j.at("name").get<std::string>();
      t.sampler = j.value("sampler", "u_" + t.name);
      t.file = (dir / j.at("file").get<std::string>()).string();
      t.filter = j.value("filter", "nearest");
      BTFC_ASSIGN_OR_RETURN(t.tex, gpu::read_ktx2(t.file));
      const gpu::GpuTexture& x = t.tex;
      const std::string fmt = j.at("format").get<std::string>();
      if (fmt != gpu::format_info(x.format).name || j.at("width").get<uint32_t>() != x.width || j.at("height").get<uint32_t>() != x.height ||
          j.at("layers").get<uint32_t>() != x.layers || j.at("levels").get<uint32_t>() != x.num_levels())
        return corrupt_data(t.file + ": KTX2 header (" + gpu::format_info(x.format).name + " " + std::to_string(x.width) + "x" +
                            std::to_string(x.height) + ", " + std::to_string(x.layers) + " layers, " + std::to_string(x.num_levels()) +
                            " levels) disagrees with manifest.json (" + j.dump() + ")");
      if (t.filter != "nearest" && t.filter != "linear") return invalid_argument(t.file + ": manifest filter '" + t.filter + "' is not nearest|linear");
      out.push_back(std::move(t));
    }
  } catch (const nlohmann::json::exception& e) {
    return corrupt_data((dir / "manifest.json").string() + ": " + e.what());
  }
  return out;
}

Status upload(GlObjects& o, const ManifestTexture& mt, int unit, bool float_linear_ok) {
  const gpu::GpuTexture& t = mt.tex;
  const gpu::FormatInfo& fi = gpu::format_info(t.format);
  const GLenum target = t.layers ? GL_TEXTURE_2D_ARRAY : GL_TEXTURE_2D;
  // Beyond the implementation's limits GL fails the upload with a bare GL_INVALID_VALUE; say which.
  GLint max_size = 0, max_layers = 0;
  glGetIntegerv(GL_MAX_TEXTURE_SIZE, &max_size);
  glGetIntegerv(GL_MAX_ARRAY_TEXTURE_LAYERS, &max_layers);
  if (t.width > uint32_t(max_size) || t.height > uint32_t(max_size) || t.layers > uint32_t(max_layers))
    return unsupported(mt.file + ": " + std::to_string(t.width) + "x" + std::to_string(t.height) + "x" + std::to_string(t.layers) +
                       " exceeds GL_MAX_TEXTURE_SIZE " + std::to_string(max_size) + " / GL_MAX_ARRAY_TEXTURE_LAYERS " +
                       std::to_string(max_layers) + " of this GL (GLES 3.0 guarantees 2048 / 256)");
  GLuint id = 0;
  glGenTextures(1, &id);
  o.textures.push_back(id);
  glActiveTexture(GLenum(GL_TEXTURE0 + unit));
  glBindTexture(target, id);
  const GLsizei levels = GLsizei(t.num_levels());
  if (t.layers) glTexStorage3D(target, levels, fi.gl_internal, GLsizei(t.width), GLsizei(t.height), GLsizei(t.layers));
  else glTexStorage2D(target, levels, fi.gl_internal, GLsizei(t.width), GLsizei(t.height));
  glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
  for (uint32_t m = 0; m < t.num_levels(); ++m) {
    // level_bytes re-encodes the decoded values: bit-exact with the file for every format.
    const std::vector<uint8_t> bytes = t.level_bytes(m);
    const GLsizei w = GLsizei(t.level_width(m)), h = GLsizei(t.level_height(m));
    if (t.layers) glTexSubImage3D(target, GLint(m), 0, 0, 0, w, h, GLsizei(t.layers), fi.gl_format, fi.gl_type, bytes.data());
    else glTexSubImage2D(target, GLint(m), 0, 0, w, h, fi.gl_format, fi.gl_type, bytes.data());
  }
  const bool linear = !fi.is_integer && mt.filter == "linear";
  if (linear && fi.is_float && fi.bytes_per_channel == 4 && !float_linear_ok)
    return unsupported(mt.file + ": linear filtering of " + fi.name + " needs GL_OES_texture_float_linear, which this GL lacks");
  const GLint mag = linear ? GL_LINEAR : GL_NEAREST;
  const GLint min = levels > 1 ? (linear ? GL_LINEAR_MIPMAP_LINEAR : GL_NEAREST_MIPMAP_NEAREST) : mag;
  glTexParameteri(target, GL_TEXTURE_MAG_FILTER, mag);
  glTexParameteri(target, GL_TEXTURE_MIN_FILTER, min);
  glTexParameteri(target, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
  glTexParameteri(target, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
  glTexParameteri(target, GL_TEXTURE_MAX_LEVEL, levels - 1);
  return gl_error(mt.file + ": upload (" + fi.name + ", " + std::to_string(levels) + " levels)");
}

// The sampler type a texture needs in GLSL.
GLenum sampler_type(const gpu::GpuTexture& t) {
  const gpu::FormatInfo& fi = gpu::format_info(t.format);
  if (fi.is_integer) return t.layers ? GL_UNSIGNED_INT_SAMPLER_2D_ARRAY : GL_UNSIGNED_INT_SAMPLER_2D;
  return t.layers ? GL_SAMPLER_2D_ARRAY : GL_SAMPLER_2D;
}

// Binds every active sampler to its unit, refusing samplers the manifest does not describe.
Status bind_samplers(GLuint prog, const std::vector<ManifestTexture>& tex, const std::string& frag_path) {
  GLint n = 0;
  glGetProgramiv(prog, GL_ACTIVE_UNIFORMS, &n);
  for (GLint i = 0; i < n; ++i) {
    char name[256];
    GLsizei len = 0;
    GLint size = 0;
    GLenum type = 0;
    glGetActiveUniform(prog, GLuint(i), sizeof name, &len, &size, &type, name);
    const std::string s(name, size_t(len));
    const bool is_sampler = type == GL_SAMPLER_2D || type == GL_SAMPLER_2D_ARRAY || type == GL_UNSIGNED_INT_SAMPLER_2D ||
                            type == GL_UNSIGNED_INT_SAMPLER_2D_ARRAY || type == GL_INT_SAMPLER_2D || type == GL_INT_SAMPLER_2D_ARRAY ||
                            type == GL_SAMPLER_3D || type == GL_SAMPLER_CUBE;
    if (!is_sampler || s.rfind("btfc_harness_q", 0) == 0) continue;
    size_t k = 0;
    while (k < tex.size() && tex[k].sampler != s) ++k;
    if (k == tex.size()) return invalid_argument(frag_path + ": sampler " + s + " is not a texture of manifest.json");
    if (type != sampler_type(tex[k].tex))
      return invalid_argument(frag_path + ": sampler " + s + " has GLSL type " + hex(type) + " but " + tex[k].file + " needs " +
                              hex(sampler_type(tex[k].tex)) + " (float vs usampler, 2D vs 2D array)");
    glUniform1i(glGetUniformLocation(prog, s.c_str()), GLint(k));
  }
  for (int q = 0; q < 3; ++q) {
    const std::string s = "btfc_harness_q" + std::to_string(q);
    glUniform1i(glGetUniformLocation(prog, s.c_str()), GLint(tex.size()) + q);
  }
  return gl_error("binding samplers");
}

Status query_texture(GlObjects& o, int unit, GLsizei w, GLsizei h, const std::vector<float>& rgba) {
  GLuint id = 0;
  glGenTextures(1, &id);
  o.textures.push_back(id);
  glActiveTexture(GLenum(GL_TEXTURE0 + unit));
  glBindTexture(GL_TEXTURE_2D, id);
  glTexStorage2D(GL_TEXTURE_2D, 1, GL_RGBA32F, w, h);
  glTexSubImage2D(GL_TEXTURE_2D, 0, 0, 0, w, h, GL_RGBA, GL_FLOAT, rgba.data());
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);  // RGBA32F: not filterable in GLES 3.0
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
  return gl_error("query texture");
}

Result<std::string> read_text(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) return io_error(path + ": cannot open");
  std::ostringstream s;
  s << f.rdbuf();
  return s.str();
}

}  // namespace

Status gl_context() {
  const Egl& e = egl();
  if (!e.status.ok()) return e.status;
  if (eglGetCurrentContext() != e.ctx && !eglMakeCurrent(e.dpy, EGL_NO_SURFACE, EGL_NO_SURFACE, e.ctx))
    return egl_fail("eglMakeCurrent (surfaceless)");
  return {};
}

std::string gl_description() {
  if (!gl_context().ok()) return "no GL";
  return std::string(reinterpret_cast<const char*>(glGetString(GL_VERSION))) + ", " +
         reinterpret_cast<const char*>(glGetString(GL_RENDERER));
}

Result<std::vector<float>> gl_eval(const std::string& export_dir, std::span<const gpu::ShaderQuery> queries) {
  BTFC_RETURN_IF_ERROR(gl_context());
  const std::filesystem::path dir(export_dir);
  BTFC_ASSIGN_OR_RETURN(std::string mtext, read_text((dir / "manifest.json").string()));
  const nlohmann::json m = nlohmann::json::parse(mtext, nullptr, false);
  if (m.is_discarded()) return corrupt_data((dir / "manifest.json").string() + ": not valid JSON");
  BTFC_ASSIGN_OR_RETURN(std::vector<ManifestTexture> tex, load_textures(m, dir));
  const std::string frag_path = (dir / m.value("/shader/file"_json_pointer, std::string("btf.frag"))).string();
  BTFC_ASSIGN_OR_RETURN(std::string frag, read_text(frag_path));
  BTFC_ASSIGN_OR_RETURN(std::string fsrc, harness_fragment(frag, frag_path));
  if (queries.empty()) return std::vector<float>{};

  GLint max_units = 0;
  glGetIntegerv(GL_MAX_TEXTURE_IMAGE_UNITS, &max_units);
  if (GLint(tex.size()) + 4 > max_units)  // + 3 query textures + the render target's unit
    return unsupported(export_dir + ": " + std::to_string(tex.size()) + " textures + 4 harness textures exceed GL_MAX_TEXTURE_IMAGE_UNITS = " +
                       std::to_string(max_units));
  const char* ext = reinterpret_cast<const char*>(glGetString(GL_EXTENSIONS));
  const bool float_linear = ext && std::strstr(ext, "GL_OES_texture_float_linear");
  while (glGetError() != GL_NO_ERROR) {
  }
  GlObjects o;
  for (size_t i = 0; i < tex.size(); ++i) BTFC_RETURN_IF_ERROR(upload(o, tex[i], int(i), float_linear));

  BTFC_ASSIGN_OR_RETURN(GLuint vs, compile(o, GL_VERTEX_SHADER, k_vertex, "harness vertex shader"));
  BTFC_ASSIGN_OR_RETURN(GLuint fs, compile(o, GL_FRAGMENT_SHADER, fsrc, frag_path + " (with BTFC_NO_MAIN + harness main)"));
  o.program = glCreateProgram();
  glAttachShader(o.program, vs);
  glAttachShader(o.program, fs);
  glLinkProgram(o.program);
  GLint linked = 0, len = 0;
  glGetProgramiv(o.program, GL_LINK_STATUS, &linked);
  if (!linked) {
    glGetProgramiv(o.program, GL_INFO_LOG_LENGTH, &len);
    std::string log(size_t(std::max(len, 1)), '\0');
    glGetProgramInfoLog(o.program, len, nullptr, log.data());
    return invalid_argument(frag_path + ": GLSL link failed:\n" + log.c_str());
  }
  glUseProgram(o.program);
  BTFC_RETURN_IF_ERROR(bind_samplers(o.program, tex, frag_path));

  // One fragment per query, 256 wide; unused fragments evaluate a harmless measured query.
  const size_t n = queries.size();
  const GLsizei W = GLsizei(std::min<size_t>(n, 256)), H = GLsizei((n + size_t(W) - 1) / size_t(W));
  std::vector<float> q0(size_t(W) * size_t(H) * 4, 0.f), q1(q0.size(), 0.f), q2(q0.size(), 0.f);
  for (size_t i = 0; i < size_t(W) * size_t(H); ++i) {
    const gpu::ShaderQuery& q = queries[std::min(i, n - 1)];
    const float qq0[4] = {q.u, q.v, float(q.light), float(q.view)}, qq1[4] = {q.wl.x, q.wl.y, q.wl.z, 0}, qq2[4] = {q.wv.x, q.wv.y, q.wv.z, 0};
    std::copy(qq0, qq0 + 4, &q0[i * 4]), std::copy(qq1, qq1 + 4, &q1[i * 4]), std::copy(qq2, qq2 + 4, &q2[i * 4]);
  }
  const int qunit = int(tex.size());
  BTFC_RETURN_IF_ERROR(query_texture(o, qunit, W, H, q0));
  BTFC_RETURN_IF_ERROR(query_texture(o, qunit + 1, W, H, q1));
  BTFC_RETURN_IF_ERROR(query_texture(o, qunit + 2, W, H, q2));

  GLuint target = 0;
  glGenTextures(1, &target);
  o.textures.push_back(target);
  glActiveTexture(GLenum(GL_TEXTURE0 + qunit + 3));  // a unit no sampler reads
  glBindTexture(GL_TEXTURE_2D, target);
  glTexStorage2D(GL_TEXTURE_2D, 1, GL_RGBA32F, W, H);
  glGenFramebuffers(1, &o.fbo);
  glBindFramebuffer(GL_FRAMEBUFFER, o.fbo);
  glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, target, 0);
  const GLenum fb = glCheckFramebufferStatus(GL_FRAMEBUFFER);
  if (fb != GL_FRAMEBUFFER_COMPLETE)
    return unsupported("GL: RGBA32F framebuffer incomplete (" + hex(fb) + "; ES 3.0 needs GL_EXT_color_buffer_float)");
  glGenVertexArrays(1, &o.vao);
  glBindVertexArray(o.vao);
  glViewport(0, 0, W, H);
  glDisable(GL_BLEND);
  glDisable(GL_DITHER);
  glDrawArrays(GL_TRIANGLES, 0, 3);
  BTFC_RETURN_IF_ERROR(gl_error(frag_path + ": draw"));
  std::vector<float> px(size_t(W) * size_t(H) * 4);
  glReadPixels(0, 0, W, H, GL_RGBA, GL_FLOAT, px.data());
  BTFC_RETURN_IF_ERROR(gl_error("glReadPixels (RGBA32F)"));
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
  std::vector<float> out(n * 3);
  for (size_t i = 0; i < n; ++i) std::copy(&px[i * 4], &px[i * 4] + 3, &out[i * 3]);
  return out;
}

}  // namespace btfc::gltest
