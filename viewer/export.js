// Loads one `btfc export` directory (docs/exports.md): manifest.json, every texture it lists
// (KTX2), and btf.frag. Each failure becomes an Error whose message names the file and the
// problem, because the page shows that message to the user as is.
import * as THREE from 'three';
import { parseKtx2 } from './ktx2.js';

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

// The sampler type each u_<name> is declared with in the shader: it decides 2D vs 2D array and
// whether the data are integers, so a manifest and a shader that disagree are caught here.
function samplerTypes(glsl) {
  const m = {};
  for (const x of glsl.matchAll(/uniform\s+(?:\w+p\s+)?([iu]?sampler2D(?:Array)?)\s+u_(\w+)\s*;/g)) m[x[2]] = x[1];
  return m;
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

// Returns { url, manifest, glsl, textures: {name: THREE texture}, info: [...] } or throws.
export async function loadExport(url) {
  if (!url.endsWith('/')) url += '/';
  const mr = await fetchOk(url + 'manifest.json', 'manifest.json');
  const text = await mr.text();
  let manifest;
  try {
    manifest = JSON.parse(text);
  } catch (e) {
    throw new Error(`manifest.json is not valid JSON (${e.message})`);
  }
  if (manifest.format !== 'btfc-export') throw new Error(`manifest.json: "format" is ${JSON.stringify(manifest.format)}, not "btfc-export"`);
  for (const key of ['codec', 'btf', 'textures', 'shader'])
    if (!(key in manifest)) throw new Error(`manifest.json: no "${key}" entry`);
  if (!Array.isArray(manifest.textures)) throw new Error('manifest.json: "textures" is not a list');
  const shaderFile = manifest.shader.file || 'btf.frag';
  const glsl = await (await fetchOk(url + shaderFile, shaderFile)).text();
  if (!/^\s*#version 300 es/.test(glsl)) throw new Error(`${shaderFile}: does not start with "#version 300 es"`);
  const samplers = samplerTypes(glsl);
  const textures = {};
  // Fetched in parallel: an export has up to ~20 files and the page waits for all of them.
  await Promise.all(manifest.textures.map(async (t) => {
    const file = t.file || `${t.name}.ktx2`;
    const k = parseKtx2(await (await fetchOk(url + file, `texture ${t.name} (${file})`)).arrayBuffer(), file);
    // The manifest and the file must agree: a stale or mixed-up export would render nonsense.
    if (k.format.name !== t.format || k.width !== t.width || k.height !== t.height || k.layers !== t.layers)
      throw new Error(`${file}: the file is ${k.format.name} ${k.width} x ${k.height} x ${k.layers} layers, ` +
        `manifest.json says ${t.format} ${t.width} x ${t.height} x ${t.layers}`);
    const sampler = samplers[t.name];
    if (!sampler) throw new Error(`${shaderFile}: declares no sampler u_${t.name} for texture ${t.name}`);
    if (/^[iu]/.test(sampler) !== Boolean(k.format.integer))
      throw new Error(`${file}: ${k.format.name} cannot be read by the shader's ${sampler} u_${t.name}`);
    textures[t.name] = makeTexture(t, k, sampler);
  }));
  return { url, manifest, glsl, textures };
}
