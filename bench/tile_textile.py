#!/usr/bin/env python3
"""A larger measured-like BTF from the shared textile, for benchmarks at sizes we have no data of.

The textile (../shared/data/textile_lurex_utia64: 64 x 64 texels, 81 x 81 directions, HDR) tiled
K x K times, every tile multiplied by its own log-normal noise (sigma 0.05 per texel and 0.05 per
value, seeded by K) so that no tile repeats another exactly: K = 2 gives 128 x 128 texels (1.3 GB
of float32), K = 4 256 x 256 (5.2 GB). Written as a raw .btfc through the Python module.

Usage: PYTHONPATH=build/python /usr/bin/python3 bench/tile_textile.py K OUT.btfc [TEXTILE_DIR]
(docs/benchmarks.md, "Byte budgets past the exact path").
"""
import sys

import numpy as np

import btfc


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    k, out = int(sys.argv[1]), sys.argv[2]
    src = sys.argv[3] if len(sys.argv) > 3 else "../shared/data/textile_lurex_utia64"
    d = np.asarray(btfc.open(src))  # (height, width, views, lights, 3)
    rng = np.random.default_rng(k)
    h, w = d.shape[:2]
    big = np.empty((k * h, k * w) + d.shape[2:], np.float32)
    for i in range(k):
        for j in range(k):
            n = rng.standard_normal(d.shape, dtype=np.float32) * np.float32(0.05)
            n += rng.standard_normal(d.shape[:2] + (1, 1, 1), dtype=np.float32) * np.float32(0.05)
            big[i * h:(i + 1) * h, j * w:(j + 1) * w] = d * np.exp(n)
    btfc.Btf(big, lights="ubo2003", views="ubo2003", hdr=True).save(out)


if __name__ == "__main__":
    main()
