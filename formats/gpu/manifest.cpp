// manifest.json of an export bundle (formats/gpu/export.h).
#include "formats/gpu/export.h"

namespace btfc::gpu {

nlohmann::json manifest_json(const ExportBundle& b) {
  using nlohmann::json;
  json m;
  m["format"] = "btfc-export";
  m["version"] = 1;
  m["btfc_version"] = BTFC_VERSION;
  m["codec"] = b.codec;
  m["spec"] = b.spec;
  m["btf"] = {{"width", b.desc.width},
              {"height", b.desc.height},
              {"channels", b.desc.channels},
              {"hdr", b.desc.hdr},
              {"light_set", b.desc.lights.name},
              {"view_set", b.desc.views.name},
              {"lights", direction_table(b.desc.lights)},
              {"views", direction_table(b.desc.views)}};
  json tex = json::array();
  for (const GpuTexture& t : b.textures) {
    const FormatInfo& fi = format_info(t.format);
    tex.push_back({{"name", t.name},
                   {"file", t.name + ".ktx2"},
                   {"sampler", "u_" + t.name},
                   {"format", fi.name},
                   {"vk_format", fi.vk_format},
                   {"gl_internal_format", fi.gl_internal},
                   {"width", t.width},
                   {"height", t.height},
                   {"layers", t.layers},
                   {"levels", t.num_levels()},
                   {"filter", t.linear_filter ? "linear" : "nearest"},
                   {"scale", t.scale},
                   {"bias", t.bias},
                   {"meaning", t.meaning},
                   {"channels", t.channel_meaning},
                   {"bytes", t.total_bytes()},
                   {"clamped_values", t.clamped}});
  }
  m["textures"] = tex;
  m["shader"] = {{"file", "btf.frag"},
                 {"language", "GLSL ES 3.00 (#version 300 es)"},
                 {"functions", {"vec3 btf_eval(vec2 uv, vec3 wl, vec3 wv)", "vec3 btf_eval_measured(vec2 uv, int light, int view)"}},
                 {"samplers", "uniform u_<texture name>, texture unit = index in 'textures'"},
                 {"uv", "texel (x, y) at ((x + 0.5) / width, (y + 0.5) / height); y = BTF image row; nearest texel"},
                 {"frame", "directions are unit vectors in the sample's tangent frame, z = surface normal"},
                 {"no_main", "#define BTFC_NO_MAIN after the #version line drops main()"},
                 {"main", "in vec2 v_uv; in vec3 v_wl, v_wv; out vec4 btf_color = vec4(btf_eval(v_uv, v_wl, v_wv), 1)"}};
  m["evaluation"] = b.evaluation;
  m["bytes"] = {{"textures", b.texture_bytes()}, {"model_payload", b.model_payload_bytes}};
  m["clamped_values"] = b.clamped();
  m["warnings"] = b.warnings;
  if (!b.scene_report.is_null()) m["scene"] = b.scene_report;
  return m;
}

}  // namespace btfc::gpu
