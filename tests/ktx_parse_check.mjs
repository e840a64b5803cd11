// Independent check of btfc's KTX2 files: npm's ktx-parse (not btfc's reader) parses every
// .ktx2 of each export directory, and this script checks it against the KTX 2.0 specification,
// the export's manifest.json and the sidecar.json written by btfc_ktx_sidecar (the exporter's
// in-memory values):
//   header    vkFormat, typeSize, pixelWidth/Height, pixelDepth 0, layerCount, faceCount 1,
//             levelCount, no supercompression
//   DFD       one basic block: Khronos vendor, version 2, RGBSDA / BT.709 / linear, 1x1x1x1
//             texel block, bytesPlane0 = channels x typeSize, one sample per channel with
//             offsets, lengths, channel ids, float / signed flags and lower / upper bounds
//   KVD       KTXwriter = "btfc <version>", btfc.codec / btfc.spec / btfc.texture
//   levels    byte lengths (computed here from the shape), uncompressedByteLength, offsets aligned
//             to lcm(4, texel size), smallest level first, FNV-1a hash of every level's bytes,
//             and the first texel of level 0 / last texel of the last level decoded by hand
//             (half floats bit by bit) equal to the exporter's stored values
//   file      ktx-parse's own writer reproduces the file byte for byte (canonical layout)
// Usage: node ktx_parse_check.mjs NODE_PREFIX WORKDIR...   (NODE_PREFIX: `npm --prefix` dir)
// Exit 0 ok, 1 a check failed, 77 ktx-parse is not installed (ctest: skipped).
import { readFileSync, readdirSync, existsSync, statSync } from 'node:fs';
import { join } from 'node:path';
import { pathToFileURL } from 'node:url';

const [prefix, ...workdirs] = process.argv.slice(2);
const pkgDir = join(prefix ?? '', 'node_modules', 'ktx-parse');
if (!prefix || !existsSync(join(pkgDir, 'package.json'))) {
  console.log(`ktx-parse is not installed under ${pkgDir}: skipped`);
  process.exit(77);
}
const pkg = JSON.parse(readFileSync(join(pkgDir, 'package.json'), 'utf8'));
const entry = pkg.exports?.['.']?.default ?? pkg.exports?.['.']?.import ?? pkg.module ?? pkg.main;
const ktx = await import(pathToFileURL(join(pkgDir, entry)).href);
console.log(`ktx-parse ${pkg.version}`);

let failures = 0, checked = 0;
const fail = (where, msg) => { failures++; console.log(`FAIL ${where}: ${msg}`); };
const expectEq = (where, what, got, want) => {
  if (got !== want) fail(where, `${what} = ${got}, expected ${want}`);
};

// IEEE half -> number, by hand (not via any library).
function halfToNumber(bits) {
  const sign = bits & 0x8000 ? -1 : 1, exp = (bits >> 10) & 0x1f, frac = bits & 0x3ff;
  if (exp === 0) return sign * frac * 2 ** -24;            // subnormal (and zero)
  if (exp === 31) return frac ? NaN : sign * Infinity;
  return sign * (1 + frac / 1024) * 2 ** (exp - 15);
}
function float32Bits(u32) { const v = new DataView(new ArrayBuffer(4)); v.setUint32(0, u32 >>> 0, true); return v.getFloat32(0, true); }
function fnv1a64(bytes) {
  let h = 0xcbf29ce484222325n;
  for (const b of bytes) h = ((h ^ BigInt(b)) * 0x100000001b3n) & 0xffffffffffffffffn;
  return h.toString(16).padStart(16, '0');
}
function decodeTexel(data, index, sc) {
  const dv = new DataView(data.buffer, data.byteOffset, data.byteLength), out = [];
  for (let c = 0; c < sc.channels; c++) {
    const at = (index * sc.channels + c) * sc.type_size;
    if (sc.is_integer) out.push(sc.type_size === 1 ? dv.getUint8(at) : sc.type_size === 2 ? dv.getUint16(at, true) : dv.getUint32(at, true));
    else if (sc.is_normalized) out.push(dv.getUint8(at) / 255);
    else if (sc.type_size === 2) out.push(halfToNumber(dv.getUint16(at, true)));
    else out.push(dv.getFloat32(at, true));
  }
  return out;
}
const gcd = (a, b) => (b ? gcd(b, a % b) : a);
const text = (v) => (typeof v === 'string' ? v : new TextDecoder().decode(v)).replace(/\0+$/, '');

function checkTexture(dir, manifest, t, sc) {
  const where = join(dir, t.file);
  const bytes = new Uint8Array(readFileSync(where));
  const c = ktx.read(bytes);
  // Header.
  expectEq(where, 'vkFormat', c.vkFormat, t.vk_format);
  expectEq(where, 'vkFormat (sidecar)', c.vkFormat, sc.vk_format);
  expectEq(where, 'typeSize', c.typeSize, sc.type_size);
  expectEq(where, 'pixelWidth', c.pixelWidth, t.width);
  expectEq(where, 'pixelHeight', c.pixelHeight, t.height);
  expectEq(where, 'pixelDepth', c.pixelDepth, 0);
  expectEq(where, 'layerCount', c.layerCount, t.layers);
  expectEq(where, 'faceCount', c.faceCount, 1);
  expectEq(where, 'levelCount', c.levelCount, t.levels);
  expectEq(where, 'levelCount (sidecar)', c.levelCount, sc.levels);
  expectEq(where, 'supercompressionScheme', c.supercompressionScheme, ktx.KHR_SUPERCOMPRESSION_NONE);
  // Data format descriptor.
  expectEq(where, 'DFD blocks', c.dataFormatDescriptor.length, 1);
  const d = c.dataFormatDescriptor[0], bits = 8 * sc.type_size;
  expectEq(where, 'DFD vendorId', d.vendorId, ktx.KHR_DF_VENDORID_KHRONOS);
  expectEq(where, 'DFD descriptorType', d.descriptorType, ktx.KHR_DF_KHR_DESCRIPTORTYPE_BASICFORMAT);
  expectEq(where, 'DFD versionNumber', d.versionNumber, ktx.KHR_DF_VERSION);
  expectEq(where, 'DFD colorModel', d.colorModel, ktx.KHR_DF_MODEL_RGBSDA);
  expectEq(where, 'DFD colorPrimaries', d.colorPrimaries, ktx.KHR_DF_PRIMARIES_BT709);
  expectEq(where, 'DFD transferFunction', d.transferFunction, ktx.KHR_DF_TRANSFER_LINEAR);
  expectEq(where, 'DFD texelBlockDimension', d.texelBlockDimension.join(','), '0,0,0,0');
  expectEq(where, 'DFD bytesPlane', d.bytesPlane.join(','), [sc.channels * sc.type_size, 0, 0, 0, 0, 0, 0, 0].join(','));
  expectEq(where, 'DFD sample count', d.samples.length, sc.channels);
  const ids = [ktx.KHR_DF_CHANNEL_RGBSDA_RED, ktx.KHR_DF_CHANNEL_RGBSDA_GREEN, ktx.KHR_DF_CHANNEL_RGBSDA_BLUE, ktx.KHR_DF_CHANNEL_RGBSDA_ALPHA];
  d.samples.forEach((s, i) => {
    const w = `${where} sample ${i}`;
    expectEq(w, 'bitOffset', s.bitOffset, i * bits);
    expectEq(w, 'bitLength (bits - 1)', s.bitLength, bits - 1);
    expectEq(w, 'channel id', s.channelType & 0x0f, ids[i]);
    expectEq(w, 'FLOAT flag', !!(s.channelType & ktx.KHR_DF_SAMPLE_DATATYPE_FLOAT), sc.is_float);
    expectEq(w, 'SIGNED flag', !!(s.channelType & ktx.KHR_DF_SAMPLE_DATATYPE_SIGNED), sc.is_float);
    expectEq(w, 'samplePosition', s.samplePosition.join(','), '0,0,0,0');
    const [lo, hi] = sc.is_float ? [float32Bits(s.sampleLower), float32Bits(s.sampleUpper)] : [s.sampleLower, s.sampleUpper];
    const [wlo, whi] = sc.is_float ? [-1, 1] : sc.is_normalized ? [0, 2 ** bits - 1] : [0, 1];
    expectEq(w, 'sampleLower', lo, wlo);
    expectEq(w, 'sampleUpper', hi, whi);
  });
  // Key / value data.
  const kv = c.keyValue;
  if (!/^btfc \d+\.\d+\.\d+/.test(text(kv.KTXwriter ?? ''))) fail(where, `KTXwriter = '${text(kv.KTXwriter ?? '')}'`);
  expectEq(where, 'btfc.texture', text(kv['btfc.texture'] ?? ''), t.name);
  expectEq(where, 'btfc.codec', text(kv['btfc.codec'] ?? ''), manifest.codec);
  expectEq(where, 'btfc.spec', text(kv['btfc.spec'] ?? ''), manifest.spec);
  // Levels: sizes from the shape, layout from the raw level index (ktx-parse does not expose it).
  const texelBytes = sc.channels * sc.type_size, align = (4 * texelBytes) / gcd(4, texelBytes);
  const raw = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  let total = 0, prevOffset = Infinity, end = 0;
  for (let m = 0; m < c.levelCount; m++) {
    const w = `${where} level ${m}`, lw = Math.max(1, t.width >> m), lh = Math.max(1, t.height >> m);
    const want = lw * lh * Math.max(1, t.layers) * texelBytes;
    const L = c.levels[m];
    expectEq(w, 'byteLength', L.levelData.byteLength, want);
    expectEq(w, 'byteLength (sidecar)', L.levelData.byteLength, sc.level_bytes[m]);
    expectEq(w, 'uncompressedByteLength', L.uncompressedByteLength, want);
    const off = Number(raw.getBigUint64(80 + 24 * m, true));
    if (off % align) fail(w, `byteOffset ${off} not aligned to ${align}`);
    if (off >= prevOffset) fail(w, `byteOffset ${off} not before level ${m - 1} (smallest level first)`);
    prevOffset = off, end = Math.max(end, off + want), total += want;
    expectEq(w, 'FNV-1a of the bytes', fnv1a64(L.levelData), sc.level_fnv1a64[m]);
  }
  expectEq(where, 'end of the last level = file size', end, bytes.byteLength);
  expectEq(where, 'manifest bytes', t.bytes, total);
  const lastLevel = c.levelCount - 1;
  const lastIndex = Math.max(1, t.width >> lastLevel) * Math.max(1, t.height >> lastLevel) * Math.max(1, t.layers) - 1;
  const spot = [[c.levels[0].levelData, 0, sc.first_texel, 'first texel of level 0'],
                [c.levels[lastLevel].levelData, lastIndex, sc.last_texel_last_level, 'last texel of the last level']];
  for (const [data, index, want, what] of spot) {
    const got = decodeTexel(data, index, sc);
    if (got.length !== want.length || got.some((v, i) => v !== want[i])) fail(where, `${what} decoded by hand = [${got}], exporter stored [${want}]`);
  }
  // ktx-parse's writer, given what it read, must give the same bytes.
  const again = ktx.write(c, { keepWriter: true });
  const n = Math.min(again.length, bytes.length);
  let i = 0;
  while (i < n && again[i] === bytes[i]) i++;
  if (i < n || again.length !== bytes.length) fail(where, `ktx-parse re-writes it differently from byte ${i} (${again.length} vs ${bytes.length} bytes)`);
  checked++;
  console.log(`ok   ${where}: ${sc.format} ${t.width}x${t.height}${t.layers ? 'x' + t.layers : ''}, ${t.levels} level(s), first texel [${sc.first_texel}]`);
}

for (const work of workdirs) {
  for (const name of readdirSync(work).sort()) {
    const dir = join(work, name);
    if (!statSync(dir).isDirectory() || !existsSync(join(dir, 'manifest.json'))) continue;
    const manifest = JSON.parse(readFileSync(join(dir, 'manifest.json'), 'utf8'));
    const sidecar = JSON.parse(readFileSync(join(dir, 'sidecar.json'), 'utf8'));
    const files = readdirSync(dir).filter((f) => f.endsWith('.ktx2')).sort();
    const listed = manifest.textures.map((t) => t.file).sort();
    if (files.join() !== listed.join()) fail(dir, `.ktx2 files [${files}] differ from the manifest's [${listed}]`);
    for (const t of manifest.textures) {
      const sc = sidecar.textures.find((s) => s.name === t.name);
      if (!sc) { fail(dir, `${t.name} missing from sidecar.json`); continue; }
      expectEq(join(dir, t.file), 'manifest format', t.format, sc.format);
      try { checkTexture(dir, manifest, t, sc); } catch (e) { fail(join(dir, t.file), `ktx-parse: ${e.message}`); }
    }
  }
}
if (checked === 0) fail('ktx_parse_check', `no .ktx2 files under ${workdirs.join(' ')}`);
console.log(`${checked} KTX2 files checked, ${failures} failure(s)`);
process.exit(failures ? 1 : 0);
