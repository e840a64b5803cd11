// Exporter: a model -> a description of what its paper's real-time renderer loads (spec
// section 6): named textures (core/gpu_texture.h), the reference GLSL shader, the evaluation
// constants. Each codec's exporter lives in its folder and fills an ExportBundle; it knows no
// file format: formats/gpu/export.h writes the bundle as KTX2 files + manifest.json + btf.frag.
//
// Shader contract (pinned; tests/gl_export_test drives every codec's shader through it):
//   - `#version 300 es` first; defining BTFC_NO_MAIN (inserted after that line) drops the
//     shader's own main() so a harness can call the functions below;
//   - one `uniform highp <sampler> u_<texture name>;` per manifest texture, bound to texture unit
//     i for the manifest's i-th texture; every other constant is baked into the shader (and listed
//     in the manifest's "evaluation" object);
//   - `vec3 btf_eval(vec2 uv, vec3 wl, vec3 wv)`: the BTF at texture coordinate uv and unit light /
//     view directions in the sample's tangent frame (z = normal), interpolated between measured
//     directions as the codec's renderer does it; `vec3 btf_eval_measured(vec2 uv, int light,
//     int view)`: at measured direction indices. uv = ((x + 0.5) / width, (y + 0.5) / height)
//     addresses texel (x, y), y = the BTF image row; nearest texel (texelFetch). Channels beyond
//     the BTF's (1-channel BTFs) are 0.
//   - the default main(): in vec2 v_uv, v_wl, v_wv -> out vec4 btf_color = (btf_eval(...), 1).
// Every exporter has a CPU emulation of its shader that reads only the bundle's stored texture
// values (ShaderQuery below); tests check emulation == model evaluation and GPU == emulation.
#pragma once
#include <functional>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "codecs/codec.h"
#include "core/gpu_texture.h"
#include "core/scene.h"

namespace btfc::gpu {

struct ExportOptions {
  // Storage of float data: rgba16f (default: half the bytes, what the papers' renderers use)
  // or rgba32f ("float").
  bool half = true;
  // Half overflow: false (default) scales a texture by a power of two when its values exceed
  // the half range (exact, listed as the texture's scale); true clamps instead (and reports it).
  bool clamp_half = false;
  // Resolution of the parabolic direction maps (Delaunay index / barycentric weight textures).
  int direction_map = 64;
  // Keep only what this scene needs (core/scene.h); the bundle's `scene_report` says what.
  std::optional<SceneMaterial> scene;
};

struct ExportBundle {
  std::string codec, spec;
  BtfDesc desc;
  std::vector<GpuTexture> textures;
  nlohmann::json evaluation;   // codec-specific: formula, constants, tables (manifest "evaluation")
  std::string glsl;            // the reference fragment shader
  std::vector<std::string> warnings;
  uint64_t model_payload_bytes = 0;
  nlohmann::json scene_report;  // null without a scene (manifest "scene")
  // Other files of the export (e.g. fmf's model.bsvtf): called with the temporary directory
  // before the manifest is written; returns manifest entries ({"file", "meaning", "bytes"...}).
  std::function<Result<nlohmann::json>(const std::string& dir)> write_extra;

  const GpuTexture* find(const std::string& name) const;
  uint64_t clamped() const;
  uint64_t texture_bytes() const;
};

// A shader query: uv plus either measured indices (light, view >= 0) or directions.
struct ShaderQuery {
  float u = 0.5f, v = 0.5f;
  Vec3 wl, wv;
  int light = -1, view = -1;
};

struct Exporter {
  const char* codec;
  Result<ExportBundle> (*build)(const Model& model, const ExportOptions& opt);
  // CPU emulation of btf_eval / btf_eval_measured (3 floats out), from the bundle only.
  void (*emulate)(const ExportBundle& bundle, const ShaderQuery& q, float* rgb);
};

// The exporter of a codec (its entry in codecs/registry.cpp), or null.
const Exporter* find_exporter(const std::string& codec);
// Builds the bundle of `model`'s codec; `unsupported` names the codec when it has no exporter.
Result<ExportBundle> build_export(const Model& model, const ExportOptions& opt);
// ---- helpers shared by the codec exporters ----

// Index (rgba16_uint: i0, i1, i2, 0) and barycentric weight (rgba32f: w0, w1, w2, 0) maps over
// the parabolic disc, n x n texels, 2 layers (0: lights, 1: views): Delaunay interpolation
// (core/interp.h, seed 000 section 4) evaluated at each texel centre.
Result<std::pair<GpuTexture, GpuTexture>> direction_maps(const BtfDesc& desc, int n);
// The texel of the direction maps a direction falls in (the shader's btfc_dir_cell()).
void direction_cell(const Vec3& d, int n, int& cx, int& cy);
// GLSL shared by the shaders: btfc_texel(uv, size), btfc_dir_cell(dir, n).
const char* glsl_common();
// A float as a GLSL literal (9 significant digits, always with '.' or an exponent).
std::string glsl_float(double v);
// A GLSL function `signature` that blends `measured_call` (an expression using il[i] and iv[j],
// the light / view indices) over the 3 x 3 Delaunay pairs of wl and wv read from u_dir_index /
// u_dir_weight (DIR_N = their size): the 9-lookup interpolation every exporter's btf_eval uses.
std::string glsl_delaunay_function(const std::string& signature, const std::string& prologue, const std::string& measured_call);
// Its CPU emulation: the same blend of measured(l, v, rgb) from the bundle's direction maps.
void emulate_delaunay(const ExportBundle& b, const Vec3& wl, const Vec3& wv, const std::function<void(int l, int v, float* rgb)>& measured,
                      float* rgb);
// uv -> texel (x, y) as the shader computes it.
void uv_texel(float u, float v, int width, int height, int& x, int& y);
// Direction tables for the manifest ([[x, y, z], ...]).
nlohmann::json direction_table(const DirectionSet& set);

}  // namespace btfc::gpu
