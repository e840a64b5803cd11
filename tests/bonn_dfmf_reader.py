#!/usr/bin/python3
"""An independent reader of Bonn's `!DFMF08FCR` files, and a check of btfc's DFMF export.

It follows the decoding steps of Bonn's own public reader, BTFLIB (github.com/cgbonn/btflib,
MATLAB), file by file, written from scratch in numpy:

  matlab/@btf/private/read_common_header.m  signature, then read_meta_data.m (struct_size,
                                            version, 3 x 80 chars, ppmm, rgb_scale_factor,
                                            cosine_flag if version > 1, xml if > 2, channel
                                            names if > 3; consumed bytes == struct_size), then
                                            read_bidir_sampling.m (nV x {theta, phi, nL,
                                            nL x (theta, phi)}), width, height, and for a
                                            signature ending in 'R' num_rotations x 3 x 3 floats
  matlab/@btf/private/read_ubo_dfmf.m       num_components, color_model (int32), color_mean[3],
                                            color_transformation_matrix (3 x 3, row-major:
                                            utils/fread_matrix.m), then per channel: u8
                                            scalar_size, u32 components, rows, cols, S, U
                                            (rows x C row-major), SxV (cols x C row-major);
                                            half values are converted to single
                                            (halfprecision(..., 'single'))
  matlab/@btf/private/decode_dfmf_texture.m img(:, c) = SxV{c} * U{c}(sub2ind([nL, nV], l, v), :)'
                                            in single precision, texel index x + w * y
                                            (reshape [w, h] then permute: row = y, no flip)
  matlab/@btf/private/undecorrelate.m       model 11 (Ylog_UdivY_VdivY): Y = exp(Y') - 1e-5,
                                            U = U' (Y + 1e-5), V = V' (Y + 1e-5), then
                                            values * mat_YUV2RGB' with
                                            [1 0 1.13983; 1 -0.39465 -0.5806; 1 2.03211 0]
                                            (models 0 and 1 too)
  btf.m decode_*                            undecorrelate, then (FMF only) restore_dynamic_range,
                                            then if cosine_flag: divide by the light's z

It deliberately shares no code with btfc (formats/bonn, codecs/fmf). Zdravko Velinov's btf.hh
(the C++ reader inside BTF_extractor) is NOT followed: for model 11 it computes
U = U' * (exp(Y') - eps) + eps and clamps RGB to [0, 1], so it cannot reproduce HDR values.

Usage:
  bonn_dfmf_reader.py FILE.btf DECODED.btfc [--tol 1e-3]
      decodes FILE.btf as above and compares with DECODED.btfc, a raw .btfc (docs/FORMAT.md,
      "Raw BTF convention") that btfc decoded from the same BTF; exits 1 when the relative L2
      difference (or the per-value difference above 1 % of the maximum, relative) exceeds tol.
"""
import struct
import sys

import numpy as np

DRR_EPS = 1e-5  # undecorrelate.m: not stored in the file
YUV2RGB = np.array([[1, 0, 1.13983], [1, -0.39465, -0.5806], [1, 2.03211, 0]], dtype=np.float32)


class Reader:
    def __init__(self, data, path):
        self.b, self.pos, self.path = data, 0, path

    def take(self, n):
        if self.pos + n > len(self.b):
            raise SystemExit(f"{self.path}: truncated at byte {self.pos} (need {n} more)")
        out = self.b[self.pos:self.pos + n]
        self.pos += n
        return out

    def u8(self):
        return self.take(1)[0]

    def u32(self):
        return struct.unpack('<I', self.take(4))[0]

    def i32(self):
        return struct.unpack('<i', self.take(4))[0]

    def f32(self, n):
        return np.frombuffer(self.take(4 * n), dtype='<f4').astype(np.float32)

    def scalars(self, n, size):
        dt = {2: '<f2', 4: '<f4', 8: '<f8'}[size]
        return np.frombuffer(self.take(size * n), dtype=dt).astype(np.float32)  # halfprecision -> single


def read_dfmf(path):
    r = Reader(open(path, 'rb').read(), path)
    sig = r.take(10).decode('ascii', 'replace')
    if sig != '!DFMF08FCR':
        raise SystemExit(f"{path}: signature {sig!r} is not !DFMF08FCR")
    # read_meta_data.m
    start = r.pos
    struct_size, version = r.u32(), r.u32()
    r.take(240)  # measurement_setup, image_sensor, light_source
    r.f32(1)     # ppmm
    r.f32(3)     # rgb_scale_factor (BTFLIB reads it and never applies it)
    meta = {'cosine_flag': r.u32() if version > 1 else 0, 'num_channels': 3}
    if version > 2:
        r.take(r.u32())  # xml
    if version > 3:
        meta['num_channels'] = r.u32()
        for _ in range(meta['num_channels']):
            r.take(r.u32())
    if r.pos - start != struct_size:
        raise SystemExit(f"{path}: meta block read {r.pos - start} bytes, struct_size says {struct_size}")
    # read_bidir_sampling.m: the light list repeats per view; the first one is used
    nV = r.u32()
    lights = None
    for _ in range(nV):
        r.f32(2)
        nL = r.u32()
        ls = r.f32(2 * nL).reshape(nL, 2)
        lights = ls if lights is None else lights
    meta['nV'], meta['nL'] = nV, lights.shape[0]
    meta['light_z'] = np.cos(lights[:, 0]).astype(np.float32)  # sph2cart2: z = cos(theta)
    meta['width'], meta['height'] = r.u32(), r.u32()
    if sig.endswith('R'):
        r.take(36 * r.u32())
    # read_ubo_dfmf.m
    r.u32()  # num_components (max)
    meta['color_model'] = r.i32()
    r.f32(3)
    r.f32(9)
    U, SxV = [], []
    for c in range(meta['num_channels']):
        size = r.u8()
        C, rows, cols = r.u32(), r.u32(), r.u32()
        r.scalars(C, size)  # S
        U.append(r.scalars(rows * C, size).reshape(rows, C))
        SxV.append(r.scalars(cols * C, size).reshape(cols, C))
    if r.pos != len(r.b):
        raise SystemExit(f"{path}: {len(r.b) - r.pos} trailing bytes")
    return meta, U, SxV


def undecorrelate(meta, values):
    """undecorrelate.m on values [n, 3] (one row per decoded value triple)."""
    m = meta['color_model']
    if m == 0:
        return values
    if m == 1:
        return values @ YUV2RGB.T
    if m == 11:
        out = values.copy()
        out[:, 0] = np.exp(values[:, 0]) - np.float32(DRR_EPS)
        out[:, 1] = values[:, 1] * (out[:, 0] + np.float32(DRR_EPS))
        out[:, 2] = values[:, 2] * (out[:, 0] + np.float32(DRR_EPS))
        return out @ YUV2RGB.T
    raise SystemExit(f"colour model {m} is not implemented by this reader")


def decode_all(meta, U, SxV):
    """Every texture (decode_dfmf_texture.m per (l, v)), as [texel, v, l, channel] float32."""
    nL, nV, w, h, nC = meta['nL'], meta['nV'], meta['width'], meta['height'], meta['num_channels']
    out = np.empty((w * h, nV, nL, nC), dtype=np.float32)
    for v in range(nV):
        lv = np.arange(nL) + nL * v  # sub2ind([nL, nV], l, v), 0-based
        ch = np.stack([SxV[c] @ U[c][lv, :].T for c in range(nC)], axis=-1)  # [texel, l, c]
        rgb = undecorrelate(meta, ch.reshape(-1, nC)).reshape(w * h, nL, nC)
        if meta['cosine_flag']:
            rgb = rgb / meta['light_z'][None, :, None]
        out[:, v] = rgb
    return out


def read_raw_btfc(path):
    """The 'data' tensor of a raw .btfc (docs/FORMAT.md): [texels, abrdf_size] float32."""
    b = open(path, 'rb').read()
    if b[:8] != b'BTFC\r\n\x1a\n':
        raise SystemExit(f"{path}: not a .btfc file")
    pos = 32
    while pos + 32 <= len(b):
        ctype = b[pos:pos + 4]
        size = struct.unpack('<Q', b[pos + 8:pos + 16])[0]
        p = pos + 32
        if ctype == b'TNSR':
            n = struct.unpack('<I', b[p:p + 4])[0]
            name = b[p + 4:p + 4 + n].decode()
            dtype, ndims = b[p + 4 + n], b[p + 5 + n]
            dims = struct.unpack(f'<{ndims}Q', b[p + 8 + n:p + 8 + n + 8 * ndims])
            h0 = 8 + n + 8 * ndims
            h = h0 + (16 - h0 % 16) % 16
            if name == 'data':
                if dtype != 1:
                    raise SystemExit(f"{path}: tensor 'data' is not f32")
                return np.frombuffer(b[p + h:p + size], dtype='<f4').reshape(dims)
        if ctype == b'END ':
            break
        pos = p + size + (16 - size % 16) % 16
    raise SystemExit(f"{path}: no 'data' tensor (not a raw .btfc)")


def main(argv):
    tol = 1e-3
    if '--tol' in argv:
        i = argv.index('--tol')
        tol = float(argv[i + 1])
        argv = argv[:i] + argv[i + 2:]
    if len(argv) != 3:
        raise SystemExit(__doc__)
    meta, U, SxV = read_dfmf(argv[1])
    ours = decode_all(meta, U, SxV).reshape(meta['width'] * meta['height'], -1)  # row = c + nC (l + nL v)
    theirs = read_raw_btfc(argv[2])
    if theirs.shape != ours.shape:
        raise SystemExit(f"shape {theirs.shape} of {argv[2]} differs from the DFMF's {ours.shape}")
    if not np.all(np.isfinite(ours)):
        raise SystemExit("the reader decoded non-finite values")
    d = ours.astype(np.float64) - theirs.astype(np.float64)
    rel_l2 = np.linalg.norm(d) / max(np.linalg.norm(theirs.astype(np.float64)), 1e-30)
    big = np.abs(theirs) > 0.01 * np.abs(theirs).max()
    rel_max = float(np.max(np.abs(d[big]) / np.abs(theirs[big]))) if big.any() else 0.0
    print(f"colour model {meta['color_model']}, {meta['width']}x{meta['height']} texels, {meta['nL']}x{meta['nV']} directions, "
          f"components {[u.shape[1] for u in U]}: rel L2 difference {rel_l2:.3g}, "
          f"max relative difference (values > 1 % of max) {rel_max:.3g}, max value {np.abs(theirs).max():.4g}")
    if not (rel_l2 <= tol and rel_max <= tol):
        print(f"FAIL: the reader and btfc disagree beyond {tol}")
        return 1
    print("ok")
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv))
