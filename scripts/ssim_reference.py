#!/usr/bin/python3
"""Reference SSIM values for the pinned tests in tests/metrics_test.cpp.

Every image pair is generated from a closed-form formula that tests/metrics_test.cpp evaluates
the same way (double arithmetic with libm's sin/cos, rounded to float32, row-major with i = row,
j = column). So both sides score bit-identical inputs. This script then scores each pair:

* pairs at least 11 x 11: scikit-image's structural_similarity with the settings core/metrics.h
  pins (gaussian_weights=True, sigma=1.5, use_sample_covariance=False, data_range=L), computed
  in float64;
* smaller pairs, which scikit-image rejects: `ssim_clipped` below, a direct numpy version of the
  clipped-window rule documented in core/metrics.cpp. Before it is trusted, it is checked
  against scikit-image on every large pair.

Run with the interpreter that has Debian's python3-skimage (/usr/bin/python3):
    /usr/bin/python3 scripts/ssim_reference.py
It prints C++ initialisers to paste into tests/metrics_test.cpp.
"""
import math

import numpy as np
import skimage
from skimage.metrics import structural_similarity

SIGMA, RADIUS, K1, K2 = 1.5, 5, 0.01, 0.03


def f_smooth(i, j):
    return 0.5 + 0.4 * math.sin(0.37 * i) * math.cos(0.23 * j)


def f_odd(i, j):
    return 0.5 + 0.3 * math.sin(0.51 * i + 0.17 * j) + 0.1 * math.cos(0.83 * j)


def f_hdr(i, j):
    return 500.0 + 450.0 * math.sin(0.21 * i) * math.cos(0.33 * j)


def f_wave(i, j):
    return 0.5 + 0.45 * math.sin(2.7 * i + 1.9 * j)


# name, height, width, a(i, j), b(i, j), data range. Mirrored in tests/metrics_test.cpp.
PAIRS = [
    ("noise", 48, 64, f_smooth, lambda i, j: f_smooth(i, j) + 0.05 * math.sin(1.3 * i + 0.7 * j), 1.0),
    ("contrast", 40, 40, f_smooth, lambda i, j: 0.25 + 0.5 * f_smooth(i, j), 1.0),
    ("odd_17x23", 17, 23, f_odd, lambda i, j: 0.9 * f_odd(i, j) + 0.03 * math.sin(2.1 * i) * math.cos(1.7 * j), 1.0),
    ("hdr", 29, 32, f_hdr, lambda i, j: f_hdr(i, j) + 40.0 * math.sin(0.9 * i + 1.1 * j), 1000.0),
    ("phase", 24, 24, f_wave, lambda i, j: 0.5 + 0.45 * math.sin(2.7 * i + 1.9 * j + 0.8), 1.0),
    ("inverted", 20, 30, f_smooth, lambda i, j: 1.0 - f_smooth(i, j), 1.0),
    # Smaller than the 11 x 11 window: scored by ssim_clipped, not scikit-image.
    ("small_7x9", 7, 9, f_odd, lambda i, j: 0.9 * f_odd(i, j) + 0.03 * math.sin(2.1 * i) * math.cos(1.7 * j), 1.0),
    ("thin_5x30", 5, 30, f_smooth, lambda i, j: f_smooth(i, j) + 0.05 * math.sin(1.3 * i + 0.7 * j), 1.0),
    ("column_30x1", 30, 1, f_odd, lambda i, j: 0.8 * f_odd(i, j) + 0.05, 1.0),
    # data_range None: the reference image's own maximum, core/metrics.h's rule for HDR images
    # (tests/metrics_test.cpp scores it through compare_btf on a 1-image HDR BTF).
    ("hdr_own_range", 29, 32, f_hdr, lambda i, j: f_hdr(i, j) + 40.0 * math.sin(0.9 * i + 1.1 * j), None),
]


def make(h, w, f):
    # float(f) in double, rounded to float32 like C++'s float(f(i, j)); scored in float64.
    return np.array([[f(i, j) for j in range(w)] for i in range(h)], dtype=np.float64).astype(np.float32).astype(np.float64)


def taps(r):
    # scipy.ndimage's Gaussian kernel (what skimage.filters.gaussian uses), truncated at radius r.
    x = np.arange(-r, r + 1, dtype=np.float64)
    g = np.exp(-0.5 / (SIGMA * SIGMA) * x ** 2)
    return g / g.sum()


def ssim_clipped(a, b, L):
    """SSIM with the window clipped per axis to the largest odd size <= min(11, extent)."""
    h, w = a.shape
    ry, rx = min(RADIUS, (h - 1) // 2), min(RADIUS, (w - 1) // 2)
    gy, gx = taps(ry), taps(rx)

    def filt(img):  # 'valid' separable correlation: only positions whose window fits
        t = sum(gy[k] * img[k:h - 2 * ry + k, :] for k in range(2 * ry + 1))
        return sum(gx[k] * t[:, k:w - 2 * rx + k] for k in range(2 * rx + 1))

    ua, ub = filt(a), filt(b)
    va, vb, vab = filt(a * a) - ua * ua, filt(b * b) - ub * ub, filt(a * b) - ua * ub
    c1, c2 = (K1 * L) ** 2, (K2 * L) ** 2
    s = (2 * ua * ub + c1) * (2 * vab + c2) / ((ua * ua + ub * ub + c1) * (va + vb + c2))
    return float(s.mean())


def main():
    print(f"// scikit-image {skimage.__version__}, numpy {np.__version__}")
    for name, h, w, fa, fb, L in PAIRS:
        a, b = make(h, w, fa), make(h, w, fb)
        if L is None:
            L = float(a.max())
        own = ssim_clipped(a, b, L)
        if min(h, w) >= 2 * RADIUS + 1:
            ref = structural_similarity(a, b, gaussian_weights=True, sigma=SIGMA,
                                        use_sample_covariance=False, data_range=L)
            assert abs(ref - own) < 1e-12, (name, ref, own)
            source = "skimage"
        else:
            ref = own
            source = "clipped"
        print(f'{{"{name}", {ref!r}}},  // {source}, {h}x{w}, L={L:g}')


if __name__ == "__main__":
    main()
