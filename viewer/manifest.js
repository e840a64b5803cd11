// The checks of a `btfc export` directory (docs/exports.md) that need no browser: manifest.json
// and every field of it the page reads, the shader's sampler declarations, and each KTX2 file
// against both. Pure (no three.js, no fetch), so that export.js runs them on what it fetched and
// tests/viewer/fuzz_export.mjs runs them under node on mutated exports. Every failure is an
// Error whose message starts with the file at fault (or names it in parentheses), because the
// page shows it as is: a hostile or damaged export must get such a message, not a TypeError
// from deep inside the page, a hang, or a huge allocation.
import { parseKtx2 } from './ktx2.js';

// Far above any exporter (mlvq: 15 textures) and any GPU's texture units; bounds the fetches.
const MAX_TEXTURES = 64;
// BTF size bound: flat mode sizes the canvas by it (width x height pixels).
const MAX_SIZE = 65536;
// A file name the manifest gives is fetched relative to the export: a plain name keeps it
// inside the export directory (no "/", no "..", no "?" or "#" changing the URL).
const PLAIN_NAME = /^[A-Za-z0-9_][A-Za-z0-9_.-]{0,127}$/;

// A value for a message. Strings clipped (a 10 MB name makes no readable message); lists and
// objects only named: String() of {"toString": 1} throws, JSON.stringify of a deeply nested
// list overflows the stack.
const clip = (s) => (s.length > 80 ? `${s.slice(0, 80)}...` : s);
function show(v) {
  if (typeof v === 'string') return JSON.stringify(clip(v));
  if (Array.isArray(v)) return 'a list';
  return v !== null && typeof v === 'object' ? 'an object' : String(v);
}
const isObject = (v) => v !== null && typeof v === 'object' && !Array.isArray(v);
const isCount = (v, lo, hi) => Number.isInteger(v) && v >= lo && v <= hi;

// manifest.json's text -> the manifest, every field the viewer reads checked for its type and
// range (export.js, main.js describe / apply / bindControls, material.js).
export function parseManifest(text) {
  const fail = (msg) => { throw new Error(`manifest.json: ${msg}`); };
  let manifest;
  try {
    manifest = JSON.parse(text);
  } catch (e) {
    throw new Error(`manifest.json is not valid JSON (${e.message})`);
  }
  // "null" parses, and `key in 5` throws: only an object has the entries below.
  if (!isObject(manifest)) fail(`not a JSON object but ${show(manifest)}`);
  if (manifest.format !== 'btfc-export') fail(`"format" is ${show(manifest.format)}, not "btfc-export"`);
  for (const key of ['codec', 'btf', 'textures', 'shader'])
    if (!(key in manifest)) fail(`no "${key}" entry`);
  if (!Array.isArray(manifest.textures)) fail('"textures" is not a list');
  // The page prints these (main.js describe): a non-string could throw in the template.
  if (typeof manifest.codec !== 'string') fail(`"codec" is ${show(manifest.codec)}, not a string`);
  if ('spec' in manifest && typeof manifest.spec !== 'string') fail(`"spec" is ${show(manifest.spec)}, not a string`);
  if ('warnings' in manifest && !(Array.isArray(manifest.warnings) && manifest.warnings.every((w) => typeof w === 'string')))
    fail('"warnings" is not a list of strings');
  const bytes = manifest.bytes;
  if (bytes !== undefined && !(isObject(bytes) && ['textures', 'model_payload'].every((k) => bytes[k] === undefined || typeof bytes[k] === 'number')))
    fail('"bytes" is not an object of byte counts');
  const btf = manifest.btf;
  if (!isObject(btf)) fail(`"btf" is ${show(btf)}, not an object`);
  // The canvas is width x height in flat mode, and the mip level of detail divides by them.
  for (const k of ['width', 'height'])
    if (!isCount(btf[k], 1, MAX_SIZE)) fail(`"btf.${k}" is ${show(btf[k])}, not a whole number in [1, ${MAX_SIZE}]`);
  for (const k of ['lights', 'views'])
    if (!Array.isArray(btf[k])) fail(`"btf.${k}" is ${show(btf[k])}, not a list of directions`);
  // lpyr: the level-of-detail slider's maximum (main.js bindControls).
  const lmax = isObject(manifest.evaluation) ? manifest.evaluation.lmax : undefined;
  if (lmax !== undefined && !isCount(lmax, 0, 31)) fail(`"evaluation.lmax" is ${show(lmax)}, not a level in [0, 31]`);
  const shader = manifest.shader;
  if (!isObject(shader)) fail(`"shader" is ${show(shader)}, not an object`);
  if (shader.file && !(typeof shader.file === 'string' && PLAIN_NAME.test(shader.file)))
    fail(`"shader.file" is ${show(shader.file)}, not a file name in the export directory`);
  if (manifest.textures.length > MAX_TEXTURES) fail(`${manifest.textures.length} textures (at most ${MAX_TEXTURES})`);
  const names = new Set();
  manifest.textures.forEach((t, i) => {
    const where = `textures[${i}]`;
    if (!isObject(t)) fail(`${where} is ${show(t)}, not an object`);
    // The shader's sampler is u_<name>: a name no sampler can have is refused here; unique, as
    // the page keys textures and uniforms by it.
    if (!(typeof t.name === 'string' && /^\w{1,128}$/.test(t.name))) fail(`${where}.name is ${show(t.name)}, not a sampler name`);
    if (names.has(t.name)) fail(`texture ${t.name} is listed twice`);
    names.add(t.name);
    if (t.file && !(typeof t.file === 'string' && PLAIN_NAME.test(t.file)))
      fail(`${where}.file is ${show(t.file)}, not a file name in the export directory`);
    if (typeof t.format !== 'string') fail(`${where}.format is ${show(t.format)}, not a format name`);
    for (const k of ['width', 'height', 'layers'])
      if (!isCount(t[k], 0, 2 ** 32 - 1)) fail(`${where}.${k} is ${show(t[k])}, not a whole number`);
    if (t.levels != null && !isCount(t.levels, 1, 32)) fail(`${where}.levels is ${show(t.levels)}, not a level count`);
  });
  return manifest;
}

export const shaderFileOf = (manifest) => manifest.shader.file || 'btf.frag';
export const textureFileOf = (t) => t.file || `${t.name}.ktx2`;

// The sampler type each u_<name> is declared with in the shader: it decides 2D vs 2D array and
// whether the data are integers, so a manifest and a shader that disagree are caught here.
// No prototype: a texture named "constructor" must not find Object's constructor as its sampler.
export function checkShader(glsl, shaderFile) {
  if (!/^\s*#version 300 es/.test(glsl)) throw new Error(`${shaderFile}: does not start with "#version 300 es"`);
  const m = Object.create(null);
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
      `manifest.json says ${clip(t.format)} ${t.width} x ${t.height} x ${t.layers} x ${t.levels ?? 1}`);
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
