#!/usr/bin/env python3
"""Writes docs/examples/sky.exr: a small lat-long HDR sky (row 0 = zenith, as btfc render --env
and btfc relight --env expect): a blue gradient, a brighter horizon, a dark ground and a sun of
radiance 200 at theta 40, phi 30. An uncompressed scanline OpenEXR (float RGB) written with the
standard library only, so no EXR binding is needed. Usage: make_sky.py OUT.exr [WIDTH HEIGHT]"""
import math
import struct
import sys


def attr(name, kind, data):
    return name.encode() + b"\0" + kind.encode() + b"\0" + struct.pack("<i", len(data)) + data


def write_exr(path, w, h, pixel):
    chans = b"".join(c.encode() + b"\0" + struct.pack("<iBBBBii", 2, 0, 0, 0, 0, 1, 1) for c in "BGR") + b"\0"
    header = b"".join([
        struct.pack("<ii", 20000630, 2),
        attr("channels", "chlist", chans),
        attr("compression", "compression", b"\0"),
        attr("dataWindow", "box2i", struct.pack("<iiii", 0, 0, w - 1, h - 1)),
        attr("displayWindow", "box2i", struct.pack("<iiii", 0, 0, w - 1, h - 1)),
        attr("lineOrder", "lineOrder", b"\0"),
        attr("pixelAspectRatio", "float", struct.pack("<f", 1.0)),
        attr("screenWindowCenter", "v2f", struct.pack("<ff", 0.0, 0.0)),
        attr("screenWindowWidth", "float", struct.pack("<f", 1.0)),
        b"\0",
    ])
    line_bytes = w * 3 * 4
    table = len(header) + 8 * h
    offsets = [table + y * (8 + line_bytes) for y in range(h)]
    with open(path, "wb") as f:
        f.write(header)
        f.write(struct.pack("<%dQ" % h, *offsets))
        for y in range(h):
            rgb = [pixel(x, y) for x in range(w)]
            f.write(struct.pack("<ii", y, line_bytes))
            for c in (2, 1, 0):  # channels in alphabetical order: B, G, R
                f.write(struct.pack("<%df" % w, *[p[c] for p in rgb]))


def main():
    out = sys.argv[1] if len(sys.argv) > 1 else "docs/examples/sky.exr"
    w, h = (int(sys.argv[2]), int(sys.argv[3])) if len(sys.argv) > 3 else (64, 32)
    sun_t, sun_p = math.radians(40), math.radians(30)
    sun = (math.sin(sun_t) * math.cos(sun_p), math.sin(sun_t) * math.sin(sun_p), math.cos(sun_t))

    def pixel(x, y):
        theta = (y + 0.5) / h * math.pi
        phi = (x + 0.5) / w * 2 * math.pi
        d = (math.sin(theta) * math.cos(phi), math.sin(theta) * math.sin(phi), math.cos(theta))
        if d[2] < 0:  # ground
            return (0.08, 0.07, 0.06)
        t = 1 - d[2]  # 0 at the zenith, 1 at the horizon
        sky = (0.25 + 0.6 * t, 0.45 + 0.45 * t, 0.9 + 0.1 * t)
        cos_sun = sum(a * b for a, b in zip(d, sun))
        glow = 200.0 if cos_sun > math.cos(math.radians(4)) else 4.0 * max(cos_sun, 0) ** 16
        return tuple(c + glow for c in sky)

    write_exr(out, w, h, pixel)
    print("wrote", out, "(%dx%d lat-long, row 0 = zenith)" % (w, h))


if __name__ == "__main__":
    main()
