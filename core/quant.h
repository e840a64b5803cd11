// Quantized, entropy-coded tensors: the container's `zq` tensor encoding (dtype code 8,
// docs/FORMAT.md "zq: quantized tensors").
//
// A zq tensor of logical shape [rows, K] (one or more dims; the last is K, the others multiply to
// rows) holds value[r][k] = step[k] * q[r][k] with integers q and one step per column ("per
// component"), so a codec chooses the precision of each column. Optionally each column is an
// image of width x height texels (rows = width * height, x fastest) coded as its orthonormal
// 8 x 8 DCT (core/dct.h; the image padded to multiples of 8 by repeating its edge): then q
// are DCT coefficients, step[k] their quantisation step, and the values are the inverse DCT
// cropped to the image. The DCT is orthonormal, so a step means the same squared error per value
// in both forms (step^2 / 12 for uniform rounding).
//
// The integers are zigzag-mapped (0, -1, 1, -2, ... -> 0, 1, 2, 3, ...), written as byte planes
// (column by column: all low bytes, then the next byte, ...; DCT columns in zigzag-frequency
// order, then block), and the planes are one zstd frame: zstd's entropy stage adapts to each
// column's statistics and its matches take the runs of zeros of coarse columns.
//
// Contracts:
//  - decode is total on hostile input: a truncated, corrupt or inconsistent encoding is a
//    corrupt_data error naming `what` and the field; the decompressed size is implied by the
//    shape, must equal the zstd frame's declared content size, and is refused (before any
//    allocation) above 2^17 times the compressed size (more than zstd can produce) or 2^36 bytes.
//  - quantize_column is round-to-nearest (ties away from zero); decode(encode(x)) reproduces the
//    dequantized values bit for bit (the in-memory model of a codec equals its file).
#pragma once
#include <algorithm>
#include <cstdint>
#include <string>
#include <vector>

#include "core/container.h"
#include "core/status.h"

namespace btfc::quant {

// How many texels a codec's step rule ("2^-bits x the signal's RMS per texel", equal error per
// stored value: fmf_quant.h, lpca.h, lpyr.h) divides the energy by: the texels, or abrdf / 16
// when a texel's ABRDF has over 16 times as many values (a few texels under many directions).
// With the texels alone the direction-side factors, abrdf / texels times as many values, take
// that many times the texel side's error: one texel of 151 x 151 directions erred 21-33 % at
// bits 8 in fmf, lpca and lpyr (docs/benchmarks.md, "Bits where they matter").
inline double step_texels(double texels, double abrdf_values) { return std::max({1.0, texels, abrdf_values / 16}); }

// A codec's step for a column whose largest |value| is max_abs, made safe: at least
// max_abs / 2^29 (the integers stay within +-2^29), a normal float, and never so large that a
// value rounded to it passes the float range: up to 2^126 while max_abs is below half the
// largest float (|value| + step / 2 stays below it), else up to 2^100. (A fixed 1e-30 .. 1e30
// clamp coded BTFs scaled past 1e30 with needlessly fine steps and those below 1e-30 with
// coarse ones.)
inline float safe_step(double step, double max_abs) {
  step = std::max(step, max_abs / 536870912.0);
  const double top = max_abs < 1.7e38 ? 0x1p126 : 0x1p100;
  return float(std::clamp(step, 0x1p-126, top));
}

struct Layout {
  bool dct = false;  // columns are images coded as 8x8 DCT coefficients
  uint32_t width = 0, height = 0;  // the image size when dct (rows = width * height)
};

// Quantizes a row-major [rows, K] float array with the K steps (each finite and > 0) and returns
// the zq tensor. `dequantized` (optional, rows * K floats) receives the values decode gives back.
// invalid_argument for bad steps, non-finite values, integers beyond +-2^30, or a dct layout
// whose size disagrees with rows. Planes of 8 MiB or more are compressed as two zstd jobs on two
// worker threads (one ordinary frame; the same bytes on every machine).
Result<Tensor> encode(std::string name, std::vector<uint64_t> shape, const float* values, const std::vector<float>& steps,
                      const Layout& layout, int zstd_level = 19, std::vector<float>* dequantized = nullptr);

// The integers (column-major: q[k * coeff_rows + i]; DCT coefficients in coded order when dct)
// and steps of a zq tensor, with its layout. `what` names the tensor in errors.
struct Decoded {
  std::vector<int32_t> q;
  std::vector<float> steps;
  Layout layout;
  uint64_t rows = 0, cols = 0, coeff_rows = 0;  // coeff_rows: integers per column (padded image when dct)
};
Result<Decoded> decode_ints(const Tensor& t, const std::string& what);

// The float values of a zq tensor, row-major [rows, K].
Result<std::vector<float>> decode(const Tensor& t, const std::string& what);

// Checks the fixed header of a zq payload against the tensor's shape without decompressing (the
// container's writer and reader use it). data_bytes: the payload size.
Status check_header(const uint8_t* data, uint64_t data_bytes, const std::vector<uint64_t>& shape, const std::string& what);

}  // namespace btfc::quant
