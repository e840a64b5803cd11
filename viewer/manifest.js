// The checks of a `btfc export` directory (docs/exports.md) that need no browser: manifest.json,
// the shader's sampler declarations, and each KTX2 file against both. Pure (no three.js, no
// fetch), so that export.js runs them on what it fetched and a fuzzer can run them under node on
// mutated exports. Every failure is an Error whose message starts with the file at fault (or
// names it in parentheses), because the page shows it as is.
import { parseKtx2 } from './ktx2.js';

// manifest.json's text -> the manifest.
export function parseManifest(text) {
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
  return manifest;
}

export const shaderFileOf = (manifest) => manifest.shader.file || 'btf.frag';
export const textureFileOf = (t) => t.file || `${t.name}.ktx2`;

// The sampler type each u_<name> is declared with in the shader: it decides 2D vs 2D array and
// whether the data are integers, so a manifest and a shader that disagree are caught here.
export function checkShader(glsl, shaderFile) {
  if (!/^\s*#version 300 es/.test(glsl)) throw new Error(`${shaderFile}: does not start with "#version 300 es"`);
  const m = {};
  for (const x of glsl.matchAll(/uniform\s+(?:\w+p\s+)?([iu]?sampler2D(?:Array)?)\s+u_(\w+)\s*;/g)) m[x[2]] = x[1];
  return m;
}

// One manifest entry `t` and its file's bytes (ArrayBuffer) -> { file, k: parseKtx2's result,
// sampler: the shader's sampler type for it }.
export function checkTexture(t, buf, samplers, shaderFile) {
  const file = textureFileOf(t);
  const k = parseKtx2(buf, file);
  // The manifest and the file must agree: a stale or mixed-up export would render nonsense.
  if (k.format.name !== t.format || k.width !== t.width || k.height !== t.height || k.layers !== t.layers ||
      k.levels !== (t.levels ?? 1))
    throw new Error(`${file}: the file is ${k.format.name} ${k.width} x ${k.height} x ${k.layers} layers x ${k.levels} levels, ` +
      `manifest.json says ${t.format} ${t.width} x ${t.height} x ${t.layers} x ${t.levels ?? 1}`);
  const sampler = samplers[t.name];
  if (!sampler) throw new Error(`${shaderFile}: declares no sampler u_${t.name} for texture ${t.name}`);
  if (/^[iu]/.test(sampler) !== Boolean(k.format.integer))
    throw new Error(`${file}: ${k.format.name} cannot be read by the shader's ${sampler} u_${t.name}`);
  return { file, k, sampler };
}

// A whole export at once, in export.js's order: `read(name)` gives a file's bytes (ArrayBuffer)
// or undefined when it is missing. Returns { manifest, shaderFile, glsl, samplers, textures:
// [{ t, file, k, sampler }] } or throws. (export.js fetches between the steps, so it calls them
// one by one.)
export function checkExport(manifestText, read) {
  const manifest = parseManifest(manifestText);
  const shaderFile = shaderFileOf(manifest);
  const src = read(shaderFile);
  if (src === undefined) throw new Error(`${shaderFile}: missing`);
  const glsl = new TextDecoder().decode(src);   // as fetch's text(): UTF-8, bad bytes replaced
  const samplers = checkShader(glsl, shaderFile);
  const textures = manifest.textures.map((t) => {
    const file = textureFileOf(t);
    const buf = read(file);
    if (buf === undefined) throw new Error(`texture ${t.name} (${file}): missing`);
    return { t, ...checkTexture(t, buf, samplers, shaderFile) };
  });
  return { manifest, shaderFile, glsl, samplers, textures };
}
