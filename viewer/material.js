// The exported btf.frag, unchanged, compiled with BTFC_NO_MAIN and a main() of the viewer's own
// (the shader contract of docs/exports.md). The viewer supplies what an export cannot know: the
// surface frame, the light and the camera; the export supplies btf_eval (and, where the codec
// has them, btf_eval_lod for lpyr's level of detail and btf_relit for lpca's environment).
import * as THREE from 'three';

// Light and display, the same formulas as codecs/render.cpp (Shading::shade, tone_map) and the
// sRGB encoding of formats/preview.cpp, so that flat mode reproduces `btfc render` pixel for pixel
// up to the export's half-float storage.
const SHADE = /* glsl */ `
uniform vec3 u_light;        // towards the light (world), unit
uniform float u_distance;    // 0: directional; else a point light at u_light * u_distance
uniform float u_intensity, u_exposure, u_lod;
uniform int u_tonemap;       // 0 none, 1 reinhard
uniform int u_light_kind;    // 0 light, 1 the export's environment (btf_relit)
uniform bool u_auto_lod;
uniform vec2 u_mip_uv;       // mip level of detail (export.js setMipLevel): that level's size / SIZE
out vec4 btfv_color;

vec3 btfv_eval(vec2 uv, vec3 wl, vec3 wv, float lod) {
#ifdef HAS_LOD
  vec3 c = btf_eval_lod(uv, wl, wv, lod);
#else
  vec3 c = btf_eval(uv * u_mip_uv, wl, wv);   // uv scaled: the chains' base level is the level shown
#endif
#ifdef GREY
  c = c.rrr;   // a 1-channel BTF fills red only (the contract); shown grey, as btfc render does
#endif
  return c;
}
// Radiance leaving surface point p (world) with frame t, b, n towards unit direction wv_world.
vec3 btfv_shade(vec2 uv, vec3 p, vec3 t, vec3 b, vec3 n, vec3 wv_world, float lod) {
  vec3 wv = vec3(dot(wv_world, t), dot(wv_world, b), dot(wv_world, n));
  if (wv.z <= 0.0) return vec3(0.0);
#ifdef HAS_RELIT
  if (u_light_kind == 1) return u_intensity * btf_relit(uv, wv);
#endif
  vec3 dir = u_light;
  float e = u_intensity;
  if (u_distance > 0.0) {
    vec3 d = u_distance * u_light - p;
    float r = length(d);
    if (r <= 0.0) return vec3(0.0);
    dir = d / r;
    e *= (u_distance / r) * (u_distance / r);   // irradiance 1 at the sample's centre
  }
  vec3 wl = vec3(dot(dir, t), dot(dir, b), dot(dir, n));
  if (wl.z <= 0.0) return vec3(0.0);
  return e * btfv_eval(uv, wl, wv, lod);
}
// Texel q wrapped into the texture (the texture tiles). GLSL's % is undefined for negative operands.
ivec2 btfv_wrap(ivec2 q, ivec2 size) { return q - size * ivec2(floor(vec2(q) / vec2(size))); }
vec4 btfv_display(vec3 c) {
  c *= exp2(u_exposure);
  if (u_tonemap == 1) {
    float L = dot(c, vec3(0.2126, 0.7152, 0.0722));
    c *= L > 0.0 ? 1.0 / (1.0 + L) : 1.0;
  }
  c = clamp(c, 0.0, 1.0);
  vec3 s = mix(12.92 * c, 1.055 * pow(c, vec3(1.0 / 2.4)) - 0.055, step(vec3(0.0031308), c));
  return vec4(s, 1.0);
}
`;

// Flat mode: `btfc render --shape flat` (codecs/render.h): one pixel per texel, orthographic, in
// texture space, every texel seen from the one direction u_view, the sample in the world xy
// plane spanning x in [-0.5, 0.5], y in [-0.5 h/w, 0.5 h/w], row 0 at +y.
const FLAT_MAIN = /* glsl */ `
uniform vec3 u_view;
uniform ivec2 u_size;
void main() {
  ivec2 px = ivec2(gl_FragCoord.xy);
  vec2 xy = vec2(float(px.x), float(u_size.y - 1 - px.y)) + 0.5;   // canvas rows go up, BTF rows down
  vec2 uv = xy / vec2(u_size);
  vec3 p = vec3(uv.x - 0.5, (0.5 - uv.y) * float(u_size.y) / float(u_size.x), 0.0);
  btfv_color = btfv_display(btfv_shade(uv, p, vec3(1, 0, 0), vec3(0, 1, 0), vec3(0, 0, 1), u_view, u_lod));
}
`;

// Sphere mode: `btfc render --shape sphere` (codecs/render.cpp) pixel for pixel: a unit sphere
// seen orthographically from u_view, the texture's axis the screen's up (u = phi / pi * tiles +
// 1/2, v = theta / pi * tiles, in texels), t = d/dphi, texels blended bilinearly (4 btf_eval).
const RSPHERE_MAIN = /* glsl */ `
uniform vec3 u_view;
uniform ivec2 u_size;
uniform int u_canvas, u_tiles;
const float BTFV_PI = 3.14159265358979;  // prefixed: exported shaders define their own PI
void main() {
  vec3 v = normalize(u_view);
  vec3 hint = abs(v.z) > 0.99 ? vec3(0, 1, 0) : vec3(0, 0, 1);
  vec3 right = normalize(cross(hint, v)), up = cross(v, right);
  ivec2 px = ivec2(gl_FragCoord.xy);
  float x = (float(px.x) + 0.5) / float(u_canvas) * 2.0 - 1.0;
  float y = 1.0 - (float(u_canvas - 1 - px.y) + 0.5) / float(u_canvas) * 2.0;   // canvas rows go up
  float r2 = x * x + y * y;
  vec3 c = vec3(0.0);
  vec3 tt = vec3(0.0);
  vec3 n = normalize(x * right + y * up + sqrt(max(1.0 - r2, 0.0)) * v);
  if (r2 < 1.0) tt = cross(up, n);
  if (dot(tt, tt) >= 1e-18) {
    vec3 t = normalize(tt), b = cross(n, t);
    float th = acos(clamp(dot(n, up), -1.0, 1.0)), ph = atan(dot(n, right), dot(n, v));
    vec2 f = vec2((ph / BTFV_PI * float(u_tiles) + 0.5) * float(u_size.x), th / BTFV_PI * float(u_tiles) * float(u_size.y)) - 0.5;
    vec2 f0 = floor(f), a = f - f0;
    for (int dy = 0; dy < 2; ++dy)
      for (int dx = 0; dx < 2; ++dx) {
        float w = (dx == 1 ? a.x : 1.0 - a.x) * (dy == 1 ? a.y : 1.0 - a.y);
        if (w == 0.0) continue;
        ivec2 q = btfv_wrap(ivec2(f0) + ivec2(dx, dy), u_size);
        c += w * btfv_shade((vec2(q) + 0.5) / vec2(u_size), n, t, b, n, v, u_lod);
      }
  }
  btfv_color = btfv_display(c);
}
`;

const MESH_MAIN = /* glsl */ `
uniform vec3 u_camera;
uniform ivec2 u_size;
uniform bool u_bilinear;
in vec3 v_pos, v_n, v_t;
in vec2 v_uv;
vec3 at_texel(ivec2 q, vec3 t, vec3 b, vec3 n, vec3 wv, float lod) {
  q = btfv_wrap(q, u_size);
  return btfv_shade((vec2(q) + 0.5) / vec2(u_size), v_pos, t, b, n, wv, lod);
}
void main() {
  vec3 n = normalize(v_n);
  if (!gl_FrontFacing) n = -n;          // the cloth's back shows the same material
  vec3 t = normalize(v_t - n * dot(v_t, n));
  vec3 b = cross(n, t);
  vec3 wv = normalize(u_camera - v_pos);
  vec2 f = v_uv * vec2(u_size);         // texel coordinates (repeats included)
  float lod = u_lod;
#ifdef HAS_LOD
  // Level of detail from the screen footprint (texels per pixel): the export's own btf_lod
  // (lpyr, seed 001 section 3.4).
  if (u_auto_lod) lod = btf_lod(max(length(dFdx(f)), length(dFdy(f))));
#endif
  vec3 c;
  if (u_bilinear) {                     // 4 texels: btf_eval itself reads the nearest one
    vec2 g = f - 0.5, a = fract(g);
    ivec2 q = ivec2(floor(g));
    c = mix(mix(at_texel(q, t, b, n, wv, lod), at_texel(q + ivec2(1, 0), t, b, n, wv, lod), a.x),
            mix(at_texel(q + ivec2(0, 1), t, b, n, wv, lod), at_texel(q + ivec2(1, 1), t, b, n, wv, lod), a.x), a.y);
  } else {
    c = at_texel(ivec2(floor(f)), t, b, n, wv, lod);
  }
  btfv_color = btfv_display(c);
}
`;

const FLAT_VERT = /* glsl */ `
in vec3 position;
void main() { gl_Position = vec4(position.xy, 0.0, 1.0); }
`;

const MESH_VERT = /* glsl */ `
uniform mat4 modelViewMatrix, projectionMatrix;
in vec3 position, normal, tangent3;
in vec2 btfuv;
out vec3 v_pos, v_n, v_t;
out vec2 v_uv;
void main() {
  v_pos = position; v_n = normal; v_t = tangent3; v_uv = btfuv;   // meshes sit at the origin, unrotated
  gl_Position = projectionMatrix * modelViewMatrix * vec4(position, 1.0);
}
`;

export function features(glsl) {
  return { lod: /\bbtf_eval_lod\s*\(/.test(glsl), relit: /\bbtf_relit\s*\(/.test(glsl) };
}

// One material per (export, kind: 'flat' | 'rsphere' | 'mesh'); `uniforms` are shared, so one
// settings change reaches all.
export function makeMaterial(exp, kind, uniforms) {
  const flat = kind !== 'mesh';   // flat and rsphere draw one full-canvas quad
  const f = features(exp.glsl);
  const body = exp.glsl.replace(/^\s*#version[^\n]*\n/, '');  // three puts "#version 300 es" first
  const defines = { BTFC_NO_MAIN: '' };
  if (f.lod) defines.HAS_LOD = '';
  if (f.relit) defines.HAS_RELIT = '';
  if (exp.manifest.btf.channels === 1) defines.GREY = '';
  const u = { ...uniforms };
  for (const name of Object.keys(exp.textures)) u[`u_${name}`] = exp.bound[name];  // shared: setMipLevel swaps levels
  u.u_mip_uv = exp.mipUv ?? { value: new THREE.Vector2(1, 1) };  // per export: its own chain's level
  return new THREE.RawShaderMaterial({
    glslVersion: THREE.GLSL3,
    defines,
    uniforms: u,
    vertexShader: flat ? FLAT_VERT : MESH_VERT,
    fragmentShader: body + SHADE + { flat: FLAT_MAIN, rsphere: RSPHERE_MAIN, mesh: MESH_MAIN }[kind],
    side: flat ? THREE.FrontSide : THREE.DoubleSide,
  });
}
