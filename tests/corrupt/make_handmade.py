#!/usr/bin/env python3
"""Writes the hand-made hostile .btfc files of tests/corrupt/ (valid CRCs, lying sizes).
Byte layout: docs/FORMAT.md. Run from anywhere; files land next to this script."""
import os, struct, zlib

HERE = os.path.dirname(os.path.abspath(__file__))

def pad16(b):
    return b + b"\0" * ((16 - len(b) % 16) % 16)

def chunk(fourcc, payload, critical=True):
    head = struct.pack("<4sIQIQ", fourcc, 1 if critical else 0, len(payload), 0, 0)
    crc = zlib.crc32(payload, zlib.crc32(head))
    return head + struct.pack("<I", crc) + pad16(payload)

def header():
    h = b"BTFC\r\n\x1a\n" + struct.pack("<HHIQI", 1, 0, 32, 0, 0)
    return h + struct.pack("<I", zlib.crc32(h))

def s(text):
    b = text.encode()
    return struct.pack("<I", len(b)) + b

def dirs(n):
    return s("custom") + struct.pack("<I", n) + b"".join(struct.pack("<3f", 0, 0, 1) for _ in range(n))

def desc(w, h, ch, nl, nv):
    return struct.pack("<IIII", w, h, ch, 0) + dirs(nl) + dirs(nv)

def codc(name, version, spec):
    return s(name) + struct.pack("<I", version) + s(spec) + s("0.1.0")

def tensor(name, dtype, dims, data):
    head = s(name) + struct.pack("<BBH", dtype, len(dims), 0) + b"".join(struct.pack("<Q", d) for d in dims)
    return pad16(head) + data

def write(name, *chunks):
    with open(os.path.join(HERE, name), "wb") as f:
        f.write(header() + b"".join(chunks) + chunk(b"END ", b""))

# A raw BTF whose DESC declares 2^40 values (4 TiB decoded) next to a 4-byte tensor: the reader
# must compare the declared shape with the stored tensor before allocating the BTF.
write("handmade_raw_desc_4tib.btfc", chunk(b"DESC", desc(1 << 20, 1 << 20, 1, 1, 1)),
      chunk(b"CODC", codc("raw", 1, "raw")), chunk(b"TNSR", tensor("data", 1, [1, 1], b"\0" * 4)))
# Tensor dims whose product overflows 64 bits (2^62 x 8 f32).
write("handmade_tensor_dims_overflow.btfc", chunk(b"DESC", desc(2, 2, 3, 1, 1)),
      chunk(b"CODC", codc("raw", 1, "raw")), chunk(b"TNSR", tensor("data", 1, [1 << 62, 8], b"\0" * 16)))
# An fmf model claiming 2^31 components in a 16-byte U tensor: the loader must not size anything
# from the claimed rank.
write("handmade_fmf_huge_rank.btfc", chunk(b"DESC", desc(2, 2, 3, 1, 1)),
      chunk(b"CODC", codc("fmf", 1, "fmf:rank=32")), chunk(b"TNSR", tensor("U.rgb", 1, [3, 1 << 31], b"")))

# A BSVTF streaming file (docs/FORMAT.md "BSVTF") of 8192 x 8192 texels in 1024-texel tiles with
# 64-texel borders (4 levels, 85 tiles) whose 86 payloads are all empty: 3.8 KB that declare
# 1 GiB of eigen-textures and 5 MB of coefficients per tile. Every CRC is valid; the reader must
# refuse raw sizes that no deflate stream of the stored size can produce, before anyone sizes a
# buffer from the geometry.
def bsvtf_huge_geometry():
    w = h = 8192
    tile, border, comps, levels, nl, nv, nb, C = 1024, 64, 4, 4, 1, 1, 1, 4
    dim = tile + 2 * border
    tf = comps * dim * dim
    tiles = [(0, 0, 0)] + [(l, tx, ty) for l in range(1, levels) for ty in range(1 << l) for tx in range(1 << l)]
    entries = 1 + len(tiles)
    hb = 80 + 12 * (nl + nv) + 280 * nb + 8
    data_off = hb + 40 * entries
    d = b""
    d += struct.pack("<BBHIIIQIIfI", 1, 0, 0, 0, 0, 0, data_off, 0, nl * nv * comps * 2, 0.0, 0)  # the packet
    for l, tx, ty in tiles:
        d += struct.pack("<BBHIIIQIIfI", 2, l, 0, 0, tx, ty, data_off, 0, tf, 1.0, 0)
    head = b"BSVTF\r\n\x1a" + struct.pack("<HHIIIIIIIIIIIIIQQ", 1, 0, hb, w, h, tile, border, comps, levels, 95, 0, 1,
                                          nl, nv, nb, entries, 0)
    head += struct.pack("<3f", 0, 0, 1) * (nl + nv)
    head += b"rgb\0\0\0\0\0" + struct.pack("<IIIf", nl * nv, C, 1, 1.0) + struct.pack("<64f", *([0.5] * 64))
    head += struct.pack("<I", zlib.crc32(d))
    head += struct.pack("<I", zlib.crc32(head))
    assert len(head) == hb
    with open(os.path.join(HERE, "handmade_bsvtf_huge_geometry.bsvtf"), "wb") as f:
        f.write(head + d)

bsvtf_huge_geometry()
