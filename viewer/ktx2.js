// KTX 2.0 reader for the uncompressed textures `btfc export` writes (formats/gpu/ktx2.h).
// Hand-written rather than three's KTX2Loader: that loader targets Basis / supercompressed
// colour textures and refuses the integer formats (r16_uint index maps, ...) the BTF shaders
// read with texelFetch. Every offset and length is checked against the file size, so a
// truncated or foreign file gives a message naming it instead of garbage on the screen.

// vkFormat -> WebGL2 upload parameters (the formats of core/gpu_texture.cpp).
// integer: read by usampler / isampler (needs NEAREST filtering to be complete).
const FORMATS = {
  9: { name: 'r8_unorm', internal: 'R8', format: 'RED', type: 'UNSIGNED_BYTE', channels: 1, bytes: 1 },
  16: { name: 'rg8_unorm', internal: 'RG8', format: 'RG', type: 'UNSIGNED_BYTE', channels: 2, bytes: 1 },
  37: { name: 'rgba8_unorm', internal: 'RGBA8', format: 'RGBA', type: 'UNSIGNED_BYTE', channels: 4, bytes: 1 },
  13: { name: 'r8_uint', internal: 'R8UI', format: 'RED_INTEGER', type: 'UNSIGNED_BYTE', channels: 1, bytes: 1, integer: true },
  74: { name: 'r16_uint', internal: 'R16UI', format: 'RED_INTEGER', type: 'UNSIGNED_SHORT', channels: 1, bytes: 2, integer: true },
  81: { name: 'rg16_uint', internal: 'RG16UI', format: 'RG_INTEGER', type: 'UNSIGNED_SHORT', channels: 2, bytes: 2, integer: true },
  95: { name: 'rgba16_uint', internal: 'RGBA16UI', format: 'RGBA_INTEGER', type: 'UNSIGNED_SHORT', channels: 4, bytes: 2, integer: true },
  98: { name: 'r32_uint', internal: 'R32UI', format: 'RED_INTEGER', type: 'UNSIGNED_INT', channels: 1, bytes: 4, integer: true },
  107: { name: 'rgba32_uint', internal: 'RGBA32UI', format: 'RGBA_INTEGER', type: 'UNSIGNED_INT', channels: 4, bytes: 4, integer: true },
  76: { name: 'r16f', internal: 'R16F', format: 'RED', type: 'HALF_FLOAT', channels: 1, bytes: 2 },
  83: { name: 'rg16f', internal: 'RG16F', format: 'RG', type: 'HALF_FLOAT', channels: 2, bytes: 2 },
  97: { name: 'rgba16f', internal: 'RGBA16F', format: 'RGBA', type: 'HALF_FLOAT', channels: 4, bytes: 2 },
  100: { name: 'r32f', internal: 'R32F', format: 'RED', type: 'FLOAT', channels: 1, bytes: 4 },
  103: { name: 'rg32f', internal: 'RG32F', format: 'RG', type: 'FLOAT', channels: 2, bytes: 4 },
  109: { name: 'rgba32f', internal: 'RGBA32F', format: 'RGBA', type: 'FLOAT', channels: 4, bytes: 4 },
};

const MAGIC = [0xab, 0x4b, 0x54, 0x58, 0x20, 0x32, 0x30, 0xbb, 0x0d, 0x0a, 0x1a, 0x0a];

// Parses `buf` (ArrayBuffer); `what` names the file in errors. Returns every mip level (`mips`,
// level i of max(1, width >> i) x max(1, height >> i) x layers texels; `data` = level 0): the
// exported shaders read level 0 with texelFetch, and the viewer shows the coarser levels of a
// chain (fmf's eigen-textures) as its level of detail by moving the texture's base level.
export function parseKtx2(buf, what) {
  const fail = (msg) => { throw new Error(`${what}: ${msg}`); };
  if (buf.byteLength < 80) fail(`truncated (${buf.byteLength} bytes, a KTX2 header is 80)`);
  const u8 = new Uint8Array(buf);
  if (!MAGIC.every((b, i) => u8[i] === b)) fail('not a KTX 2.0 file (wrong identifier)');
  const dv = new DataView(buf);
  const u32 = (o) => dv.getUint32(o, true);
  const u64 = (o) => {
    const hi = dv.getUint32(o + 4, true);
    if (hi) fail('offset beyond 4 GiB');
    return dv.getUint32(o, true);
  };
  const vkFormat = u32(12), width = u32(20), height = u32(24), depth = u32(28);
  const layers = u32(32), faces = u32(36), levels = Math.max(1, u32(40)), scheme = u32(44);
  const f = FORMATS[vkFormat];
  if (!f) fail(`vkFormat ${vkFormat} is not one btfc writes`);
  if (scheme !== 0) fail(`supercompression ${scheme} is not supported (btfc writes none)`);
  if (depth !== 0 || faces !== 1) fail('3D and cube textures are not supported');
  // btfc writes 2D textures: a 0 would be a 1D texture (height) or an invalid file (width).
  if (width === 0 || height === 0) fail(`${width} x ${height} texels (btfc writes 2D textures, at least 1 x 1)`);
  // At most a full chain down to 1 x 1 (the KTX2 rule): the page makes one GPU texture per level,
  // and levels of one texel each could all share the same bytes.
  let chain = 1;
  for (let s = Math.max(width, height); s > 1; s = Math.floor(s / 2)) ++chain;
  if (levels > chain) fail(`${levels} mip levels, a ${width} x ${height} texture has at most ${chain}`);
  if (80 + 24 * levels > buf.byteLength) fail('truncated level index');
  // KVD: key\0value\0 pairs, each with a u32 length and 4-byte padding.
  const kv = {};
  const kvdOff = u32(56), kvdLen = u32(60);
  if (kvdOff + kvdLen > buf.byteLength) fail('key/value data beyond the end of the file');
  const utf8 = new TextDecoder();   // one for all entries: the KVD may hold thousands of tiny ones
  for (let p = kvdOff; p + 4 <= kvdOff + kvdLen;) {
    const n = u32(p);
    // An entry must stay inside the KVD (else it would read the level data as text).
    if (p + 4 + n > kvdOff + kvdLen) fail(`key/value entry at byte ${p} (${n} bytes) runs past the key/value data`);
    const s = utf8.decode(u8.subarray(p + 4, p + 4 + n));
    const z = s.indexOf('\0');
    if (z > 0) kv[s.slice(0, z)] = s.slice(z + 1).replace(/\0$/, '');
    p += 4 + n + ((4 - (n % 4)) % 4);
  }
  const nLayers = Math.max(1, layers);
  const Typed = f.type === 'FLOAT' ? Float32Array : f.type === 'UNSIGNED_INT' ? Uint32Array
    : f.bytes === 2 ? Uint16Array : Uint8Array;
  const mips = [];
  for (let i = 0; i < levels; ++i) {
    const off = u64(80 + 24 * i), len = u64(88 + 24 * i);
    // Not width >> i: >> works on int32, so a width of 2^31 or more would turn negative (1 texel).
    const w = Math.max(1, Math.floor(width / 2 ** i)), h = Math.max(1, Math.floor(height / 2 ** i));
    const expect = w * h * nLayers * f.channels * f.bytes;
    if (len !== expect) fail(`level ${i} holds ${len} bytes, ${w} x ${h} x ${nLayers} ${f.name} needs ${expect}`);
    if (off + len > buf.byteLength) fail(`truncated: level ${i} ends at byte ${off + len}, the file has ${buf.byteLength}`);
    mips.push({ width: w, height: h, data: new Typed(buf.slice(off, off + len)) });  // a copy: aligned for the typed array
  }
  return { vkFormat, format: f, width, height, layers, levels, kv, mips, data: mips[0].data };
}
