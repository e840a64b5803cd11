// Deterministic mutation fuzzer for the web viewer's export checks (issue #25: a fuzz target per
// input a user or a file controls). A `btfc export` directory is what `btfc view` hands the
// page; viewer/manifest.js checks it without a browser (export.js runs the same functions on
// what it fetched). This script mutates seed exports (manifest.json JSON-aware and raw, the KTX2
// files' header / level index / key-value data / size, btf.frag's sampler declarations) and
// runs each mutated export through checkExport (which calls viewer/ktx2.js's parseKtx2).
//
// A case passes when the export is accepted, and then every field the page reads is usable
// (pageUse below mirrors main.js), or when it is refused with a plain Error whose message names
// a file (manifest.json, the shader or a texture, as the page shows it to the user). A case
// fails on: TypeError / RangeError / SyntaxError / anything not a plain Error, a message naming
// no file, more than --time-limit ms, an allocation above 4 x the export's bytes + 1 MiB (a size
// taken from a field no bytes back), or a hang / out-of-memory (the cases run in a worker thread
// watched from here; a stuck worker is killed and the run goes on after its case).
//
// Case i is a function of (--seed, i) only, so a run is reproducible and any case can be rebuilt.
// Failing cases are saved as export directories (the mutated files, plus case.json describing
// the mutation and the outcome) under --artifacts; --replay runs saved ones again.
//
// Usage: node fuzz_export.mjs [--iterations N] [--seed S] [--artifacts DIR] [--time-limit MS]
//                             SEED_DIR...         (an export, or a directory of exports)
//        node fuzz_export.mjs --replay CASE_DIR...   (in this thread: a case that hangs, hangs)
// Defaults: 10000 cases (10-15 s on 2 busy cores with btfc's 7 fixture exports), seed 1,
// artifacts in ./fuzz-artifacts, 1000 ms per case, the first 10 failures saved (--keep).
// Exit 0: no failure; 1: failures; 77: no seed export found (ctest: skipped); 2: bad usage.
import fs from 'node:fs';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { Worker, isMainThread, parentPort, workerData } from 'node:worker_threads';
import { checkExport } from '../../viewer/manifest.js';

const SELF = fileURLToPath(import.meta.url);

// ---------- options ----------
function parseArgs(argv) {
  const o = { iterations: 10000, seed: 1, artifacts: 'fuzz-artifacts', timeLimit: 1000, keep: 10, dirs: [], replay: false };
  for (let i = 0; i < argv.length; ++i) {
    const a = argv[i], v = () => { if (i + 1 >= argv.length) usage(`${a} needs a value`); return argv[++i]; };
    if (a === '--iterations') o.iterations = Number(v());
    else if (a === '--seed') o.seed = Number(v());
    else if (a === '--artifacts') o.artifacts = v();
    else if (a === '--time-limit') o.timeLimit = Number(v());
    else if (a === '--keep') o.keep = Number(v());
    else if (a === '--replay') o.replay = true;
    else if (a.startsWith('--')) usage(`unknown option ${a}`);
    else o.dirs.push(a);
  }
  for (const [k, opt] of [['iterations', '--iterations'], ['seed', '--seed'], ['timeLimit', '--time-limit'], ['keep', '--keep']])
    if (!Number.isInteger(o[k]) || o[k] < 0) usage(`${opt} must be a whole number`);
  return o;
}
function usage(msg) {
  console.error(`fuzz_export.mjs: ${msg}\nusage: node fuzz_export.mjs [--iterations N] [--seed S] [--artifacts DIR] ` +
    '[--time-limit MS] [--keep N] SEED_DIR...\n       node fuzz_export.mjs --replay CASE_DIR...');
  process.exit(2);
}

// ---------- seeds ----------
// An export directory -> { name, files: Map(file name -> Uint8Array) } with manifest.json, the
// shader and every texture its manifest lists (not previews, model files, sidecar.json); `all`
// (a saved case, whose manifest may name anything): every file but case.json.
function loadExportDir(dir, all = false) {
  const files = new Map();
  const add = (f) => {
    const p = path.join(dir, f);
    if (!files.has(f) && fs.existsSync(p) && fs.statSync(p).isFile()) files.set(f, new Uint8Array(fs.readFileSync(p)));
  };
  add('manifest.json');
  if (all) {
    for (const f of fs.readdirSync(dir)) if (f !== 'case.json') add(f);
    return { name: path.basename(dir), dir, files };
  }
  try {
    const m = JSON.parse(Buffer.from(files.get('manifest.json')).toString('utf8'));
    add(m.shader?.file || 'btf.frag');
    for (const t of m.textures) add(t.file || `${t.name}.ktx2`);
  } catch {
    // a seed whose manifest is broken: the seed check reports it
  }
  return { name: path.basename(dir), dir, files };
}
function findSeeds(dirs) {
  const seeds = [];
  for (const d of dirs) {
    if (fs.existsSync(path.join(d, 'manifest.json'))) seeds.push(loadExportDir(d));
    else if (fs.existsSync(d) && fs.statSync(d).isDirectory())
      for (const e of fs.readdirSync(d).sort())
        if (fs.existsSync(path.join(d, e, 'manifest.json'))) seeds.push(loadExportDir(path.join(d, e)));
  }
  return seeds;
}

// ---------- deterministic random numbers ----------
// mulberry32, seeded by a hash of (seed, case): case i never depends on cases before it.
function rngFor(seed, i) {
  let h = Math.imul(seed ^ 0x9e3779b9, 0x85ebca6b) ^ Math.imul(i + 1, 0xc2b2ae35);
  h = Math.imul(h ^ (h >>> 16), 0x7feb352d);
  let a = (h ^ (h >>> 15)) >>> 0;
  const next = () => {
    a = (a + 0x6d2b79f5) >>> 0;
    let t = a;
    t = Math.imul(t ^ (t >>> 15), t | 1);
    t ^= t + Math.imul(t ^ (t >>> 7), t | 61);
    return ((t ^ (t >>> 14)) >>> 0) / 4294967296;
  };
  const r = {
    next,
    int: (n) => Math.floor(next() * n),           // [0, n)
    pick: (list) => list[Math.floor(next() * list.length)],
    chance: (p) => next() < p,
  };
  return r;
}

// ---------- mutations ----------
const DEEP = '"@@deep@@"';   // replaced in the text by a deeply nested list (JSON.stringify would recurse)
const DEEP_TEXT = '['.repeat(64);
const INTERESTING = [
  null, true, false, 0, -1, 1, 2, 0.5, -0, 255, 65535, 65536, 65537, 2 ** 31 - 1, 2 ** 31, 2 ** 32 - 1, 2 ** 32,
  2 ** 53, 1e308, -1e308, 5e-324, '', 'x', 'NaN', 'Infinity', '16', 'btf.frag', 'manifest.json', '../manifest.json',
  '/etc/passwd', 'a/b.ktx2', '?x=1', '__proto__', 'constructor', 'toString', 'hasOwnProperty', 'r16_uint',
  'rgba32f', 'x'.repeat(100000), 'é\u0000\ud800', [], {}, [1, 2, 3], ['a', 'b'], new Array(10000).fill(null),
  { toString: 1, valueOf: 1 }, { width: 1 }, DEEP.slice(1, -1),
];
const interesting = (r) => structuredClone(r.pick(INTERESTING));   // a copy: later mutations edit it
// The fields the viewer reads: half the JSON mutations hit one of these.
function viewerPaths(m) {
  const p = [['format'], ['codec'], ['spec'], ['btf'], ['btf', 'width'], ['btf', 'height'], ['btf', 'lights'],
    ['btf', 'views'], ['btf', 'channels'], ['textures'], ['shader'], ['shader', 'file'], ['evaluation'],
    ['evaluation', 'lmax'], ['bytes'], ['bytes', 'textures'], ['bytes', 'model_payload'], ['warnings']];
  if (Array.isArray(m?.textures))
    m.textures.forEach((_, i) => {
      p.push(['textures', i]);
      for (const k of ['name', 'file', 'format', 'width', 'height', 'layers', 'levels']) p.push(['textures', i, k]);
    });
  return p;
}
function allPaths(v, prefix = [], out = [], budget = { n: 4000 }) {
  if (budget.n-- <= 0) return out;
  out.push(prefix);
  if (v !== null && typeof v === 'object')
    for (const k of Object.keys(v)) allPaths(v[k], [...prefix, Array.isArray(v) ? Number(k) : k], out, budget);
  return out;
}
function getAt(v, p) { for (const k of p) v = v?.[k]; return v; }
// Sets (or, with value undefined, deletes) the value at path p; own properties only, so a key
// "__proto__" is a plain key as in JSON.
function setAt(root, p, value) {
  if (!p.length) return value;
  const parent = getAt(root, p.slice(0, -1));
  if (parent === null || typeof parent !== 'object') return root;
  const k = p[p.length - 1];
  if (value === undefined) {
    if (Array.isArray(parent)) parent.splice(k, 1); else delete parent[k];
  } else Object.defineProperty(parent, k, { value, enumerable: true, writable: true, configurable: true });
  return root;
}
const fmtPath = (p) => (p.length ? p.map((k) => (typeof k === 'number' ? `[${k}]` : `.${k}`)).join('') : '(root)');
const brief = (v) => { const s = v === undefined ? 'undefined' : JSON.stringify(v); return s.length > 60 ? `${s.slice(0, 60)}... (${s.length} chars)` : s; };

function mutateManifestJson(r, text) {
  let m;
  // Already nested deep by an earlier mutation: parsing and walking it again costs seconds.
  if (text.includes(DEEP_TEXT)) return mutateBytes(r, new TextEncoder().encode(text), 'manifest.json');
  try { m = JSON.parse(text); } catch { return mutateBytes(r, new TextEncoder().encode(text), 'manifest.json'); }
  const ops = [];
  for (let n = 1 + (r.chance(0.3) ? r.int(3) : 0); n > 0; --n) {
    const p = r.chance(0.5) ? r.pick(viewerPaths(m)) : r.pick(allPaths(m));
    const kind = r.int(8);
    if (kind === 0) { m = setAt(m, p, undefined); ops.push(`delete ${fmtPath(p)}`); }
    else if (kind <= 3) { const v = interesting(r); m = setAt(m, p, v); ops.push(`${fmtPath(p)} = ${brief(v)}`); }
    else if (kind === 4) {   // a value of another field: type confusion with realistic values
      const from = r.pick(allPaths(m)); const v = structuredClone(getAt(m, from));
      m = setAt(m, p, v); ops.push(`${fmtPath(p)} = value of ${fmtPath(from)}`);
    } else if (kind === 5 && Array.isArray(m?.textures) && m.textures.length > 1) {   // mixed-up entries
      const i = r.int(m.textures.length), j = r.int(m.textures.length), k = r.pick(['name', 'file', 'format', 'width', 'layers', 'levels']);
      const a = m.textures[i], b = m.textures[j];   // entries an earlier op made non-objects are left alone
      if (a !== null && typeof a === 'object' && b !== null && typeof b === 'object') {
        [a[k], b[k]] = [b[k], a[k]];
        ops.push(`swap textures[${i}].${k} and textures[${j}].${k}`);
      }
    } else if (kind === 6 && Array.isArray(m?.textures) && m.textures.length) {   // duplicated / many entries
      const n2 = r.pick([1, 2, 63, 300]), i = r.int(m.textures.length);
      for (let c = 0; c < n2; ++c) m.textures.push(structuredClone(m.textures[i]));
      ops.push(`textures[${i}] appended ${n2} times`);
    } else {   // a new key, also prototype names
      const k = r.pick(['__proto__', 'constructor', 'toString', 'valueOf', 'extra', 'file', 'levels']);
      const parent = getAt(m, p);
      const target = parent !== null && typeof parent === 'object' && !Array.isArray(parent) ? p : [];
      const v = interesting(r);
      m = setAt(m, [...target, k], v); ops.push(`${fmtPath([...target, k])} = ${brief(v)} (added)`);
    }
  }
  let out;
  try {
    out = JSON.stringify(m, null, r.pick([0, 1, 2])) ?? '';
  } catch {   // a list nested deep by a mutation that did not contain the marker text: stringify recurses
    return mutateBytes(r, new TextEncoder().encode(text), 'manifest.json');
  }
  if (out.includes(DEEP)) out = out.replace(DEEP, '['.repeat(20000) + ']'.repeat(20000));
  return { bytes: new TextEncoder().encode(out), what: `manifest.json: ${ops.join('; ') || 'unchanged'}` };
}

// Raw bytes: flips, truncation, insertions, chunk deletion / duplication, bad UTF-8.
function mutateBytes(r, src, file) {
  let b = src.slice();
  const ops = [];
  for (let n = 1 + r.int(3); n > 0; --n) {
    const kind = r.int(6), at = r.int(b.length + 1);
    if (kind === 0 && b.length) { const i = Math.min(at, b.length - 1), v = r.int(256); ops.push(`byte ${i}: ${b[i]} -> ${v}`); b[i] = v; }
    else if (kind === 1 && b.length) { const i = Math.min(at, b.length - 1), bit = r.int(8); b[i] ^= 1 << bit; ops.push(`bit ${bit} of byte ${i} flipped`); }
    else if (kind === 2) { b = b.slice(0, at); ops.push(`truncated to ${at} bytes`); }
    else if (kind === 3) {
      const ins = r.pick([[0xff], [0xc3], [0], [0x22], [0x5c], [...new TextEncoder().encode('1e999')], [...new TextEncoder().encode('NaN')], [0x7b], [0x5b]]);
      const nb = new Uint8Array(b.length + ins.length); nb.set(b.subarray(0, at)); nb.set(ins, at); nb.set(b.subarray(at), at + ins.length);
      b = nb; ops.push(`inserted [${ins}] at ${at}`);
    } else if (kind === 4) { const len = r.int(64); const nb = new Uint8Array(b.length - Math.min(len, b.length - at)); nb.set(b.subarray(0, at)); nb.set(b.subarray(at + len), at); b = nb; ops.push(`deleted ${len} bytes at ${at}`); }
    else { const len = 1 + r.int(256); const chunk = b.slice(at, at + len); const nb = new Uint8Array(b.length + chunk.length); nb.set(b.subarray(0, at)); nb.set(chunk, at); nb.set(b.subarray(at), at + chunk.length); b = nb; ops.push(`duplicated ${chunk.length} bytes at ${at}`); }
  }
  return { bytes: b, what: `${file}: ${ops.join('; ')}` };
}

// KTX2: header fields (offsets of the KTX 2.0 header), level index entries, KVD entry lengths,
// sizes scaled so only "is it backed by bytes" stops them, truncation, foreign file swapped in.
const HEADER = { vkFormat: 12, typeSize: 16, width: 20, height: 24, depth: 28, layers: 32, faces: 36, levels: 40,
  scheme: 44, dfdOff: 48, dfdLen: 52, kvdOff: 56, kvdLen: 60, sgdOff: 64, sgdOffHi: 68, sgdLen: 72 };
const U32S = [0, 1, 2, 3, 4, 7, 8, 16, 31, 32, 33, 255, 256, 4096, 65535, 65536, 0x7fffffff, 0x80000000, 0x80000001,
  0xfffffff0, 0xfffffffc, 0xffffffff];
function mutateKtx(r, src, file, others) {
  if (src.length < 80) return mutateBytes(r, src, file);
  let b = src.slice();
  const dv = () => new DataView(b.buffer, b.byteOffset, b.byteLength);
  // Out of range (an earlier op truncated the file): reads 0, writes nothing.
  const get = (o) => (o + 4 <= b.length ? dv().getUint32(o, true) : 0);
  const put = (o, v) => { if (o + 4 <= b.length) dv().setUint32(o, v >>> 0, true); };
  const ops = [];
  const value = (old) => r.pick([...U32S, old + 1, old - 1, old * 2, old >>> 1, r.int(2 ** 32), 9, 13, 74, 98, 100, 109]);
  for (let n = 1 + (r.chance(0.4) ? 1 + r.int(2) : 0); n > 0; --n) {
    const levels = Math.max(1, b.length >= 80 ? get(40) : 1);
    const kind = b.length >= 80 ? r.int(10) : -1;
    if (kind < 0) break;
    if (kind <= 2) {   // one header field
      const [name, off] = r.pick(Object.entries(HEADER)); const v = value(get(off)) >>> 0;
      ops.push(`header ${name}: ${get(off)} -> ${v}`); put(off, v);
    } else if (kind === 3) {   // one level index word: offset / length / uncompressed length, low or high half
      const lv = r.int(levels), word = r.int(6), off = 80 + 24 * lv + 4 * word;
      if (off + 4 <= b.length) { const v = value(get(off)) >>> 0; ops.push(`level ${lv} index word ${word}: ${get(off)} -> ${v}`); put(off, v); }
    } else if (kind === 4) {   // a KVD entry's length
      const kvdOff = get(56), kvdLen = get(60);
      if (kvdLen >= 4 && kvdOff + kvdLen <= b.length) {
        let p = kvdOff; const entries = [];
        while (p + 4 <= kvdOff + kvdLen && entries.length < 32) { entries.push(p); p += 4 + get(p) + ((4 - (get(p) % 4)) % 4); }
        const e = r.pick(entries); const v = value(get(e)) >>> 0; ops.push(`KVD entry at ${e}: length ${get(e)} -> ${v}`); put(e, v);
      }
    } else if (kind === 5) {   // a bigger texture, level 0's length to match (only the file size can
      // refuse it), or of one texel (what a reader whose size arithmetic wraps would expect)
      const w = r.pick([2 ** 15, 2 ** 16, 2 ** 20, 2 ** 31, 2 ** 32 - 1]), h = r.pick([1, 1, 2 ** 15, 2 ** 16, 2 ** 31]);
      const name = FORMAT_NAMES[get(12)] ?? 'rgba';
      const texel = (get(16) || 1) * (name.startsWith('rgba') ? 4 : name.startsWith('rg') ? 2 : 1) * Math.max(1, get(32));
      put(20, w); put(24, h);
      put(88, r.chance(0.5) ? Math.min(0xffffffff, w * h * texel) : texel); put(92, 0);
      ops.push(`size ${w} x ${h}, level 0 length ${get(88)}`);
    } else if (kind === 6) {   // many levels, the index pointing at bytes the file has (or not)
      const n2 = r.pick([2, 8, 31, 32, 33, 1000, 0xffff]);
      put(40, n2); ops.push(`levels ${levels} -> ${n2}`);
      if (r.chance(0.5)) {   // every level aliasing level 0's bytes
        const o0 = get(80), l0 = get(88), nb = new Uint8Array(Math.max(b.length, 80 + 24 * Math.min(n2, 4096)));
        nb.set(b); b = nb;
        for (let i = 1; i < Math.min(n2, 4096); ++i) { put(80 + 24 * i, o0); put(88 + 24 * i, l0); }
        ops.push('every level aliasing level 0');
      }
    } else if (kind === 7) {   // a 1 x 1 texture whose N levels all alias one texel: every level is valid on its own
      const n2 = r.pick([2, 32, 33, 1000]), texel = get(88) / Math.max(1, get(20) * get(24)) || 1;
      const o0 = get(80), nb = new Uint8Array(Math.max(b.length, 80 + 24 * n2));
      nb.set(b); b = nb;
      put(20, 1); put(24, 1); put(40, n2);
      for (let i = 0; i < n2; ++i) { put(80 + 24 * i, o0); put(84 + 24 * i, 0); put(88 + 24 * i, texel); put(92 + 24 * i, 0); }
      ops.push(`1 x 1 with ${n2} levels of ${texel} bytes at ${o0}`);
    } else if (kind === 8) {   // truncated inside the header, the level index, the KVD or the data
      const cut = r.pick([r.int(80), 80 + r.int(24 * levels), get(56) + r.int(Math.max(1, get(60))), r.int(b.length)]);
      b = b.slice(0, Math.min(cut, b.length)); ops.push(`truncated to ${b.length} bytes`);
    } else {   // another texture's file under this name: a mixed-up export
      const [name, other] = r.pick(others); b = other.slice(); ops.push(`replaced by ${name}`);
    }
  }
  if (!ops.length) return mutateBytes(r, src, file);
  if (r.chance(0.2)) { const m = mutateBytes(r, b, file); return { bytes: m.bytes, what: `${file}: ${ops.join('; ')}; ${m.what.slice(file.length + 2)}` }; }
  return { bytes: b, what: `${file}: ${ops.join('; ')}` };
}

// btf.frag: sampler declarations removed, renamed, retyped; version line; scanner stress.
function mutateShader(r, src, file) {
  let s = new TextDecoder().decode(src);
  const decls = [...s.matchAll(/uniform\s+(?:\w+p\s+)?([iu]?sampler2D(?:Array)?)\s+u_(\w+)\s*;/g)];
  let what;
  const kind = r.int(8);
  if (kind === 0 && decls.length) { const d = r.pick(decls); s = s.replace(d[0], ''); what = `removed ${d[0]}`; }
  else if (kind === 1 && decls.length) {
    const d = r.pick(decls), to = r.pick(['x', 'constructor', '__proto__', 'toString', d[2] + '_', 'u_' + d[2], r.pick(decls)[2]]);
    s = s.replace(d[0], d[0].replace(`u_${d[2]}`, `u_${to}`)); what = `u_${d[2]} renamed u_${to}`;
  } else if (kind === 2 && decls.length) {
    const d = r.pick(decls), to = r.pick(['sampler2D', 'sampler2DArray', 'usampler2D', 'usampler2DArray', 'isampler2D', 'samplerCube', 'sampler3D']);
    s = s.replace(d[0], d[0].replace(d[1], to)); what = `u_${d[2]} declared ${to}`;
  } else if (kind === 3) {
    const to = r.pick(['', '#version 100\n', '#version 300 es\n', '\ufeff#version 300 es\n', '#version 300\n']);
    s = s.replace(/^\s*#version[^\n]*\n/, to); what = `version line -> ${JSON.stringify(to)}`;
  } else if (kind === 4) {   // the sampler scanner on pathological text
    const junk = r.pick(['uniform ' + ' '.repeat(200000), ('uniform ' + 'p'.repeat(50) + ' ').repeat(4000),
      'uniform highp ' + 'w'.repeat(200000), 'uniform highp sampler2D u_' + 'a'.repeat(200000)]);
    s += junk; what = `appended ${junk.length} chars of scanner stress`;
  } else if (kind === 5 && decls.length) { const d = r.pick(decls); s = s.replace(d[0], d[0] + '\n' + d[0].replace(d[1], 'usampler2D')); what = `u_${d[2]} declared twice`; }
  else return mutateBytes(r, src, file);
  return { bytes: new TextEncoder().encode(s), what: `${file}: ${what}` };
}

// vkFormat -> the manifest's format name (viewer/ktx2.js FORMATS).
const FORMAT_NAMES = { 9: 'r8_unorm', 16: 'rg8_unorm', 37: 'rgba8_unorm', 13: 'r8_uint', 74: 'r16_uint', 81: 'rg16_uint',
  95: 'rgba16_uint', 98: 'r32_uint', 107: 'rgba32_uint', 76: 'r16f', 83: 'rg16f', 97: 'rgba16f', 100: 'r32f', 103: 'rg32f', 109: 'rgba32f' };
// manifest.json with `file`'s entry set to what the KTX2 header `ktx` says, or null.
function agreeManifest(manifestBytes, file, ktx) {
  if (ktx.length < 80) return null;
  let m;
  const text = new TextDecoder().decode(manifestBytes);
  if (text.includes(DEEP_TEXT)) return null;   // see mutateManifestJson
  try { m = JSON.parse(text); } catch { return null; }
  const t = Array.isArray(m?.textures) && m.textures.find((x) => x && (x.file || `${x.name}.ktx2`) === file);
  if (!t) return null;
  const dv = new DataView(ktx.buffer, ktx.byteOffset, ktx.byteLength), u32 = (o) => dv.getUint32(o, true);
  Object.assign(t, { width: u32(20), height: u32(24), layers: u32(32), levels: Math.max(1, u32(40)), format: FORMAT_NAMES[u32(12)] ?? t.format });
  try {
    return new TextEncoder().encode(JSON.stringify(m));
  } catch {   // nested too deep by an earlier mutation
    return null;
  }
}

// Case i: a seed and 1 to 3 mutated files of it.
function makeCase(seeds, seed, i) {
  const r = rngFor(seed, i);
  const s = seeds[r.int(seeds.length)];
  const files = new Map(s.files);
  const names = [...files.keys()];
  const ktx = names.filter((f) => f.endsWith('.ktx2'));
  const shader = names.find((f) => f !== 'manifest.json' && !f.endsWith('.ktx2'));
  const what = [];
  const targets = [];
  for (let n = r.chance(0.1) ? 2 + r.int(2) : 1; n > 0; --n) {
    const x = r.next();
    const target = x < 0.3 ? 'manifest.json' : x < 0.4 ? 'manifest-raw' : x < 0.85 && ktx.length ? r.pick(ktx) : shader ?? 'manifest.json';
    const file = target === 'manifest-raw' ? 'manifest.json' : target;
    const src = files.get(file);
    let m;
    if (target === 'manifest.json') m = mutateManifestJson(r, new TextDecoder().decode(src));
    else if (target === 'manifest-raw') m = mutateBytes(r, src, 'manifest.json (raw)');
    else if (file.endsWith('.ktx2')) {
      m = mutateKtx(r, src, file, ktx.filter((f) => f !== file).map((f) => [f, files.get(f)]).concat([[file, src]]));
      // Half the time the manifest is made to agree with the mutated header, so the mutation
      // gets past the manifest cross-check to the level index and the data (as fuzz_model_load
      // repairs CRCs).
      if (r.chance(0.5)) {
        const fixed = agreeManifest(files.get('manifest.json'), file, m.bytes);
        if (fixed) { files.set('manifest.json', fixed); m.what += ' (manifest.json made to agree)'; }
      }
    }
    else m = mutateShader(r, src, file);
    files.set(file, m.bytes);
    what.push(m.what);
    targets.push(target === 'manifest-raw' ? 'manifest' : file.endsWith('.ktx2') ? 'ktx2' : file === 'manifest.json' ? 'manifest' : 'shader');
  }
  return { i, seed: s.name, files, what, kind: targets[0] };
}

// ---------- running one case ----------
// Allocation guard: ArrayBuffer slices and typed arrays above `cap` bytes throw this (not an
// Error, so it can never pass as a clean refusal).
class AllocationGuard { constructor(msg) { this.message = msg; } }
let allocCap = Infinity;
function installGuard() {
  const slice = ArrayBuffer.prototype.slice;
  ArrayBuffer.prototype.slice = function (a, b) {
    const len = Math.max(0, Math.min(b ?? this.byteLength, this.byteLength) - Math.max(0, a ?? 0));
    if (len > allocCap) throw new AllocationGuard(`ArrayBuffer.slice of ${len} bytes (cap ${allocCap})`);
    return slice.call(this, a, b);
  };
  for (const T of ['Uint8Array', 'Uint16Array', 'Uint32Array', 'Int32Array', 'Float32Array', 'Float64Array', 'ArrayBuffer']) {
    const C = globalThis[T];
    const per = C.BYTES_PER_ELEMENT ?? 1;
    globalThis[T] = new Proxy(C, {
      construct(target, args, nt) {
        if (typeof args[0] === 'number' && args[0] * per > allocCap) throw new AllocationGuard(`new ${T}(${args[0]}) (cap ${allocCap} bytes)`);
        return Reflect.construct(target, args, nt);
      },
    });
  }
}

// What the page does with an accepted export (main.js describe / apply / bindControls,
// export.js setMipLevel, material.js): must not throw nor produce a non-finite size.
function pageUse(exp, files) {
  const m = exp.manifest, b = m.bytes || {};
  const kb = (x) => (x === undefined ? '?' : `${(x / 1024).toFixed(1)} KiB`);
  const rows = [m.codec, m.spec, `${m.btf.width} x ${m.btf.height} texels, ${m.btf.lights.length} lights x ${m.btf.views.length} views`,
    `${kb(b.textures)} in ${m.textures.length} KTX2 files`, kb(b.model_payload)];
  if (m.warnings && m.warnings.length) rows.push(m.warnings.join('; '));
  rows.map((v) => String(v).replace(/[<&]/g, (c) => `&#${c.charCodeAt(0)};`)).join('');
  const z = Math.max(1, Math.floor(512 / Math.max(m.btf.width, m.btf.height)));
  if (!Number.isFinite(z) || !Number.isFinite(m.btf.width * z)) throw new Error(`page: flat-mode canvas size ${m.btf.width} x ${z}`);
  const lod = Math.max(0, m.evaluation?.lmax ?? 0);
  if (!Number.isFinite(lod)) throw new Error(`page: lod slider max ${lod}`);
  if (m.btf.channels === 1) { /* material.js: GREY */ }
  for (const { file, k, t } of exp.textures) {
    const size = files.get(file).length;
    let total = 0;
    if (k.mips.length !== k.levels) throw new Error(`page: ${file} has ${k.mips.length} mips, ${k.levels} levels`);
    // export.js makes one GPU texture per level: no more than a full chain down to 1 x 1.
    if (k.mips.length > Math.floor(Math.log2(Math.max(k.width, k.height, 1))) + 1)
      throw new Error(`page: ${file} is ${k.width} x ${k.height} with ${k.mips.length} levels (a full mip chain has fewer)`);
    for (const [i, mip] of k.mips.entries()) {
      const want = mip.width * mip.height * Math.max(1, k.layers) * k.format.channels;
      if (!(mip.width >= 1 && mip.height >= 1) || mip.data.length !== want)
        throw new Error(`page: ${file} level ${i} is ${mip.width} x ${mip.height} with ${mip.data.length} values, needs ${want}`);
      if (i === 0 && (mip.width !== k.width || mip.height !== k.height)) throw new Error(`page: ${file} level 0 is ${mip.width} x ${mip.height}, the file says ${k.width} x ${k.height}`);
      total += mip.data.byteLength;
    }
    if (total > 2 * size) throw new Error(`page: ${file} (${size} bytes) gave ${total} bytes of texels`);
    if (k.width !== t.width) throw new Error('page: width check bypassed');
  }
}

// An exception's message and its first frame (a 10000-frame RangeError stack is no help).
const firstLines = (e) => (e?.stack ? e.stack.split('\n').slice(0, 2).map((l) => l.trim()).join(' ') : String(e));

// -> { outcome: 'accepted' | 'rejected' | 'failure', detail, ms }
function runCase(c, timeLimit) {
  const requested = new Set(['manifest.json']);
  const read = (name) => {
    requested.add(name);
    const b = c.files.get(name);
    return b === undefined ? undefined : b.buffer.slice(b.byteOffset, b.byteOffset + b.byteLength);
  };
  let total = 0;
  for (const b of c.files.values()) total += b.length;
  const t0 = performance.now();
  let res;
  allocCap = 4 * total + (1 << 20);
  try {
    const manifestBytes = c.files.get('manifest.json');
    const exp = checkExport(manifestBytes ? new TextDecoder().decode(manifestBytes) : '', read);
    allocCap = Infinity;
    try {
      pageUse(exp, c.files);
      res = { outcome: 'accepted', detail: 'accepted' };
    } catch (e) {
      res = { outcome: 'failure', detail: `accepted, but the page cannot use it: ${firstLines(e)}` };
    }
  } catch (e) {
    allocCap = Infinity;
    if (e instanceof AllocationGuard) res = { outcome: 'failure', detail: `huge allocation: ${e.message}` };
    else if (!(e instanceof Error) || e.constructor !== Error) res = { outcome: 'failure', detail: `not a plain Error: ${firstLines(e)}` };
    else {
      const msg = e.message;
      const named = [...requested].some((f) => msg.startsWith(`${f}:`) || msg.startsWith(`${f} `) || msg.includes(`(${f})`));
      res = named ? { outcome: 'rejected', detail: msg } : { outcome: 'failure', detail: `the message names no file: ${msg}` };
    }
  }
  res.ms = performance.now() - t0;
  if (res.ms > timeLimit && res.outcome !== 'failure') res = { outcome: 'failure', detail: `took ${res.ms.toFixed(0)} ms (limit ${timeLimit}): ${res.detail}`, ms: res.ms };
  return res;
}

function saveArtifact(dir, c, res) {
  const d = path.join(dir, `case-${c.i}`);
  fs.rmSync(d, { recursive: true, force: true });
  fs.mkdirSync(d, { recursive: true });
  for (const [f, b] of c.files) fs.writeFileSync(path.join(d, f), b);
  fs.writeFileSync(path.join(d, 'case.json'), JSON.stringify({ case: c.i, seed_export: c.seed, mutations: c.what,
    outcome: res.detail.slice(0, 4000) }, null, 1) + '\n');
  return d;
}
const clip = (s, n = 300) => (s.length > n ? `${s.slice(0, n)}...` : s);

// ---------- worker: runs cases [start, iterations), reports through shared counters ----------
// Counters: 0 case running, 1 its start time (ms, low 31 bits), 2 done flag, then per kind
// (manifest, ktx2, shader) accepted / rejected at 3 + 2 * kind.
const KINDS = ['manifest', 'ktx2', 'shader'];
if (!isMainThread) {
  const { o, start, shared } = workerData;
  const st = new Int32Array(shared);
  const seeds = findSeeds(o.dirs);
  installGuard();
  for (let i = start; i < o.iterations; ++i) {
    Atomics.store(st, 0, i);
    Atomics.store(st, 1, Date.now() & 0x7fffffff);
    let c;
    try {
      c = makeCase(seeds, o.seed, i);
    } catch (e) {   // a bug of this script, not of the viewer: reported as a failure all the same
      parentPort.postMessage({ i, harness: true, detail: `fuzzer bug building the case: ${firstLines(e)}` });
      continue;
    }
    const res = runCase(c, o.timeLimit);
    if (res.outcome === 'failure') parentPort.postMessage({ i, seed: c.seed, what: c.what, detail: res.detail });
    else Atomics.add(st, 3 + 2 * KINDS.indexOf(c.kind) + (res.outcome === 'rejected' ? 1 : 0), 1);
  }
  Atomics.store(st, 2, 1);
} else {
  main();
}

async function main() {
  const o = parseArgs(process.argv.slice(2));
  if (o.replay) return replay(o);
  const seeds = findSeeds(o.dirs);
  if (!seeds.length) { console.log(`no export directory (with manifest.json) under ${o.dirs.join(' ') || '(none given)'}: skipped`); process.exit(77); }
  // Every seed must load as is: else the fuzzer would only explore one refusal.
  for (const s of seeds) {
    const res = runCase({ i: -1, seed: s.name, files: s.files, what: ['(unmutated)'] }, 10 * o.timeLimit);
    if (res.outcome !== 'accepted') { console.log(`FAIL seed ${s.dir} does not load: ${res.detail}`); process.exit(1); }
  }
  console.log(`fuzz_export: ${seeds.length} seed exports (${seeds.map((s) => s.name).join(', ')}), seed ${o.seed}, ${o.iterations} cases`);
  const failures = [];
  const t0 = performance.now();
  const shared = new SharedArrayBuffer(4 * (3 + 2 * KINDS.length));
  const st = new Int32Array(shared);
  const hangMs = Math.max(3 * o.timeLimit, 3000);
  let start = 0;
  while (start < o.iterations) {
    Atomics.store(st, 2, 0);
    Atomics.store(st, 0, start);
    // resourceLimits: an unchecked size that allocates on the JS heap kills the worker, not the run.
    const w = new Worker(SELF, { workerData: { o, start, shared }, resourceLimits: { maxOldGenerationSizeMb: 1024 } });
    w.on('message', (f) => failures.push(f));
    const next = await new Promise((resolve) => {
      let lastCase = -1, since = Date.now();
      const timer = setInterval(() => {
        const cur = Atomics.load(st, 0);
        if (cur !== lastCase) { lastCase = cur; since = Date.now(); }
        else if (!Atomics.load(st, 2) && Date.now() - since > hangMs) {
          clearInterval(timer);
          w.terminate();
          failures.push({ i: cur, detail: `no result after ${hangMs} ms: hang (worker killed)`, rebuild: true });
          resolve(cur + 1);
        }
      }, 50);
      w.on('error', (e) => {
        clearInterval(timer);
        const cur = Atomics.load(st, 0);
        failures.push({ i: cur, detail: `worker died: ${e?.code ?? ''} ${e?.message ?? e}`, rebuild: true });
        resolve(cur + 1);
      });
      w.on('exit', () => { clearInterval(timer); resolve(o.iterations); });
    });
    // messages posted just before an exit arrive before 'exit'; a killed worker's case restarts after it
    start = Atomics.load(st, 2) ? o.iterations : next;
  }
  const secs = (performance.now() - t0) / 1000;
  failures.sort((a, b) => a.i - b.i);
  let accepted = 0, rejected = 0;
  const perKind = KINDS.map((k, j) => { accepted += st[3 + 2 * j]; rejected += st[4 + 2 * j]; return `${k} ${st[3 + 2 * j]} / ${st[4 + 2 * j]}`; });
  console.log(`iterations ${o.iterations} in ${secs.toFixed(1)} s (${(o.iterations / secs).toFixed(0)} cases/s)`);
  console.log(`accepted ${accepted}, rejected with a clean error ${rejected}, failures ${failures.length}`);
  console.log(`by mutated file (accepted / rejected): ${perKind.join(', ')}`);
  if (failures.length) {
    fs.mkdirSync(o.artifacts, { recursive: true });
    for (const f of failures.slice(0, o.keep)) {
      if (f.harness) { console.log(`FAIL case ${f.i}: ${f.detail}`); continue; }
      const c = makeCase(seeds, o.seed, f.i);   // rebuilt from (seed, i): the same bytes the worker ran
      const d = saveArtifact(o.artifacts, c, f);
      console.log(`FAIL case ${f.i} (seed export ${c.seed}): ${c.what.map((w) => clip(w, 200)).join(' | ')}\n     ${clip(f.detail, 600)}\n     saved: ${d} (replay: node ${path.relative(process.cwd(), SELF)} --replay ${d})`);
    }
    if (failures.length > o.keep) console.log(`(${failures.length - o.keep} more failures not saved; --keep N)`);
  }
  process.exit(failures.length ? 1 : 0);
}

function replay(o) {
  if (!o.dirs.length) usage('--replay needs case directories');
  installGuard();
  let bad = 0;
  for (const d of o.dirs) {
    const s = loadExportDir(d, true);
    const info = fs.existsSync(path.join(d, 'case.json')) ? JSON.parse(fs.readFileSync(path.join(d, 'case.json'), 'utf8')) : {};
    const res = runCase({ i: info.case ?? -1, seed: s.name, files: s.files, what: info.mutations ?? [] }, o.timeLimit);
    console.log(`${res.outcome === 'failure' ? 'FAIL' : 'ok  '} ${d} (${res.ms.toFixed(1)} ms): ${res.outcome}: ${clip(res.detail, 1000)}`);
    if (info.mutations) console.log(`     mutations: ${info.mutations.map((w) => clip(w, 200)).join(' | ')}`);
    if (res.outcome === 'failure') ++bad;
  }
  process.exit(bad ? 1 : 0);
}
