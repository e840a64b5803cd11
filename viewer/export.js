// Loads one `btfc export` directory (docs/exports.md): manifest.json, every texture it lists
// (KTX2), and btf.frag. Each failure becomes an Error whose message names the file and the
// problem, because the page shows that message to the user as is. The checks themselves are in
// manifest.js (no three.js, so the fuzzer runs them under node); this file fetches and uploads.
import * as THREE from 'three';
import { checkShader, checkTexture, parseManifest, shaderFileOf, textureFileOf } from './manifest.js';

async function fetchOk(url, what) {
  let r;
  try {
    r = await fetch(url, { cache: 'no-store' });
  } catch (e) {
    throw new Error(`${what}: cannot fetch ${url} (${e.message})`);
  }
  if (!r.ok) throw new Error(`${what}: ${r.status === 404 ? 'missing' : 'cannot be read'} (HTTP ${r.status} for ${url})`);
  return r;
}

function makeTexture(t, k, sampler) {
  const isArray = sampler.endsWith('Array');
  const tex = isArray ? new THREE.DataArrayTexture(k.data, k.width, k.height, Math.max(1, k.layers))
    : new THREE.DataTexture(k.data, k.width, k.height);
  const f = k.format;
  tex.internalFormat = f.internal;
  tex.format = {
    RED: THREE.RedFormat, RG: THREE.RGFormat, RGBA: THREE.RGBAFormat,
    RED_INTEGER: THREE.RedIntegerFormat, RG_INTEGER: THREE.RGIntegerFormat, RGBA_INTEGER: THREE.RGBAIntegerFormat,
  }[f.format];
  tex.type = {
    UNSIGNED_BYTE: THREE.UnsignedByteType, UNSIGNED_SHORT: THREE.UnsignedShortType, UNSIGNED_INT: THREE.UnsignedIntType,
    HALF_FLOAT: THREE.HalfFloatType, FLOAT: THREE.FloatType,
  }[f.type];
  // The shaders address texels exactly (texelFetch); nearest keeps integer textures complete.
  tex.magFilter = tex.minFilter = THREE.NearestFilter;
  tex.generateMipmaps = false;
  tex.flipY = false;            // KTX2 rows are top-down, texel y = BTF image row: upload as stored
  tex.unpackAlignment = 1;      // r16 rows of odd width are not 4-byte aligned
  tex.colorSpace = THREE.NoColorSpace;
  tex.needsUpdate = true;
  return tex;
}

// One texture per level of a mip chain (level 0 = the texture itself), each holding that level
// as its only level. The exported shaders read level 0 with texelFetch, so showing level l is
// binding level l's texture in place of the chain and scaling uv (setMipLevel). (Moving one
// chain texture's TEXTURE_BASE_LEVEL behind three.js's back read wrong texels in the browser
// test, half the coordinate range black, although base level + texelFetch works in plain WebGL2
// on the same SwiftShader: separate textures keep three's texture state its own.)
function makeLevels(t, k, sampler) {
  const levels = [makeTexture(t, k, sampler)];
  for (let i = 1; i < k.mips.length; ++i) {
    const m = k.mips[i];
    levels.push(makeTexture(t, { ...k, width: m.width, height: m.height, data: m.data, mips: [m] }, sampler));
  }
  levels[0].userData.levels = levels.length;
  return levels;
}

// Returns { url, manifest, glsl, textures: {name: THREE texture (level 0)}, mips: {name: [texture per
// level]}, bound: {name: the uniform the materials share} } or throws.
export async function loadExport(url) {
  if (!url.endsWith('/')) url += '/';
  const mr = await fetchOk(url + 'manifest.json', 'manifest.json');
  const manifest = parseManifest(await mr.text());
  const shaderFile = shaderFileOf(manifest);
  const glsl = await (await fetchOk(url + shaderFile, shaderFile)).text();
  const samplers = checkShader(glsl, shaderFile);
  // Keyed by texture name: no prototype, so a texture named "__proto__" is one more entry.
  const textures = Object.create(null), mips = Object.create(null);
  // Fetched in parallel: an export has up to ~20 files and the page waits for all of them.
  await Promise.all(manifest.textures.map(async (t) => {
    const file = textureFileOf(t);
    const buf = await (await fetchOk(url + file, `texture ${t.name} (${file})`)).arrayBuffer();
    const { k, sampler } = checkTexture(t, buf, samplers, shaderFile);
    const levels = makeLevels(t, k, sampler);
    textures[t.name] = levels[0];
    mips[t.name] = levels;
  }));
  // The uniforms the materials share: setMipLevel swaps a chain's level in for all of them.
  const bound = Object.create(null);
  for (const [name, tex] of Object.entries(textures)) bound[name] = { value: tex };
  return { url, manifest, glsl, textures, mips, bound };
}

// Puts every level of every texture on the GPU now (not at the first draw that binds it), so a
// level-of-detail change does not stall on an upload. Returns the levels each texture has, by name.
export function uploadMips(renderer, exp) {
  const levels = {};
  for (const [name, list] of Object.entries(exp.mips)) {
    for (const tex of list) renderer.initTexture(tex);
    levels[name] = list.length;
  }
  return levels;
}

// Shows mip level `level` (clamped to each chain) of every chain of the BTF's size, the textures
// btf_eval indexes by uv: binds that level's texture and returns the uv scale (that level's
// size / SIZE) under which the export's btf_eval, unchanged, addresses the level's texels.
export function setMipLevel(exp, level) {
  const btf = exp.manifest.btf;
  let scale = [1, 1];
  for (const [name, list] of Object.entries(exp.mips)) {
    if (list.length < 2 || list[0].image.width !== btf.width || list[0].image.height !== btf.height) continue;
    const l = Math.min(level, list.length - 1);
    exp.bound[name].value = list[l];
    scale = [list[l].image.width / btf.width, list[l].image.height / btf.height];
  }
  return scale;
}

// Levels of detail an export's mip chains offer: the chains' length when every texture of the
// BTF's size has one (they are the ones btf_eval indexes by uv), else 1.
export function mipLevels(exp) {
  const btf = exp.manifest.btf;
  const own = Object.values(exp.mips).filter((l) => l[0].image.width === btf.width && l[0].image.height === btf.height);
  return own.length && own.every((l) => l.length > 1) ? Math.min(...own.map((l) => l.length)) : 1;
}
