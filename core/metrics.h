// Error metrics between a reference BTF and a reconstruction of the same shape.
//
// RMSE over all values; relative L2 = ||a - b||_F / ||a||_F; PSNR = 20 log10(peak / RMSE) where
// peak = 1 for LDR data (values in [0, 1] from 8-bit sources: !desc.hdr and no reference value
// > 1) and, for HDR data (desc.hdr or any reference value > 1), peak = the maximum reference
// value over the whole BTF (1 if that is <= 0); the "peak" field says which was used.
//
// SSIM: Wang et al. 2004 on luminance Y = 0.2126 R + 0.7152 G + 0.0722 B (first channel when
// channels != 3), 11x11 Gaussian window sigma 1.5, K1 = 0.01, K2 = 0.03, mean over the positions
// where the window lies fully inside the image (identical to scikit-image's
// structural_similarity(gaussian_weights=True, sigma=1.5, use_sample_covariance=False,
// data_range=L), which crops the same border); images smaller than 11 x 11 use a window clipped
// to the image. mean_ssim is the mean over all (light, view) images. The dynamic range L is
// chosen per image:
//   - LDR data (as for the PSNR peak): L = 1, the 8-bit source range, for every image;
//   - HDR data: L = the maximum of that reference image's luminance (the range SSIM sees). One
//     BTF-wide peak would not rank codecs: with highlights hundreds of times the median, C1 and
//     C2 = (K L)^2 swamp the variances of the ordinary images, and every codec scored 0.99+ on
//     the HDR textile. Per-image ranges are what the independent measure of issue 22 uses.
//   - an HDR reference image whose luminance maximum is <= 0 (all black, e.g. every light below
//     the horizon): L = the BTF-wide peak. Its own range is empty, and L = 1 would depend on the
//     units; against the whole BTF's range, errors there are scored on the data's scale and an
//     exact reconstruction still gives 1.
#pragma once
#include <string>

#include "core/btf.h"

namespace btfc {

struct Metrics {
  double rmse = 0;
  double rel_l2 = 0;
  double psnr = 0;       // dB; +inf when identical
  double peak = 1;       // the peak used for PSNR (and the SSIM range of LDR data / black HDR images)
  // How mean_ssim chose each image's dynamic range (see above).
  enum class SsimRange { ldr_one, per_image_max } ssim_range = SsimRange::ldr_one;
  double mean_ssim = 1;  // over all images
  double max_abs = 0;
};

Result<Metrics> compare_btf(const Btf& reference, const Btf& test, bool with_ssim = true);

// SSIM of two single-channel images (row-major, w x h) with dynamic range L (L <= 0 or
// non-finite is taken as 1).
double ssim_gray(const float* a, const float* b, int w, int h, double L);

}  // namespace btfc
