#!/usr/bin/python3
"""MSSIM of a decoded BTF against its reference, measured independently of btfc's metrics.

MSSIM as issue 22 measures it: luminance SSIM (Y = 0.2126 R + 0.7152 G + 0.0722 B), scikit-image's
structural_similarity with an 11 x 11 Gaussian window (sigma 1.5, population covariance), data range =
the reference image's maximum luminance, mean over all (light, view) images. Images whose
reference is all zero are skipped (counted in the output). Also prints the relative L2 of RGB.

Inputs are raw .btfc files (docs/FORMAT.md "Raw BTF convention": one f32 TNSR "data" of shape
[num_texels, channels * lights * views], texel = x + width y, row = c + channels (l + lights v)):
    build/btfc compress IN -c raw -o ref.btfc          # or any raw .btfc
    build/btfc decompress model.btfc -o test.btfc
    /usr/bin/python3 scripts/mssim.py ref.btfc test.btfc [--width W] [--channels 3]
The container is parsed here (chunk walk, TNSR header), not by btfc.
"""
import argparse
import struct
import sys

import numpy as np
from skimage.metrics import structural_similarity


def read_raw_btfc(path):
    with open(path, "rb") as f:
        buf = f.read()
    if buf[:8] != b"BTFC\r\n\x1a\n":
        sys.exit(f"{path}: not a .btfc file")
    off = 32
    while off + 32 <= len(buf):
        ctype = buf[off:off + 4]
        size = struct.unpack_from("<Q", buf, off + 8)[0]
        p = off + 32
        if ctype == b"TNSR":
            n = struct.unpack_from("<I", buf, p)[0]
            name = buf[p + 4:p + 4 + n].decode()
            dtype, ndims = buf[p + 4 + n], buf[p + 5 + n]
            dims = struct.unpack_from("<" + "Q" * ndims, buf, p + 8 + n)
            h0 = 8 + n + 8 * ndims
            h = h0 + (16 - h0 % 16) % 16
            if name == "data":
                if dtype != 1 or ndims != 2:
                    sys.exit(f"{path}: tensor 'data' is not a 2D f32 tensor (a model? decompress it first)")
                a = np.frombuffer(buf, dtype="<f4", count=dims[0] * dims[1], offset=p + h)
                return a.reshape(dims[0], dims[1])
        if ctype == b"END ":
            break
        off = p + size + (16 - size % 16) % 16
    sys.exit(f"{path}: no tensor 'data'")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("reference")
    ap.add_argument("test")
    ap.add_argument("--width", type=int, default=0, help="texels per row (default: square)")
    ap.add_argument("--channels", type=int, default=3)
    a = ap.parse_args()
    ref, tst = read_raw_btfc(a.reference), read_raw_btfc(a.test)
    if ref.shape != tst.shape:
        sys.exit(f"shapes differ: {ref.shape} vs {tst.shape}")
    nt, rows = ref.shape
    w = a.width or int(round(nt ** 0.5))
    if nt % w:
        sys.exit(f"{nt} texels do not fill rows of {w}")
    hgt, c = nt // w, a.channels
    wts = np.array([0.2126, 0.7152, 0.0722]) if c == 3 else np.array([1.0])
    # Luminance images: [images, height, width]
    yr = np.tensordot(ref.astype(np.float64).reshape(nt, rows // c, c), wts, axes=([2], [0])).T.reshape(-1, hgt, w)
    yt = np.tensordot(tst.astype(np.float64).reshape(nt, rows // c, c), wts, axes=([2], [0])).T.reshape(-1, hgt, w)
    vals, skipped = [], 0
    for i in range(yr.shape[0]):
        L = yr[i].max()
        if L <= 0:
            skipped += 1
            continue
        vals.append(structural_similarity(yr[i], yt[i], gaussian_weights=True, sigma=1.5, use_sample_covariance=False,
                                          data_range=L))
    d = ref.astype(np.float64) - tst.astype(np.float64)
    rel = np.sqrt((d * d).sum() / (ref.astype(np.float64) ** 2).sum())
    print(f"mssim {np.mean(vals):.4f} rel_l2 {rel:.4f} images {len(vals)} skipped_black {skipped}")


if __name__ == "__main__":
    main()
