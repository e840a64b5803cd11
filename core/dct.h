// 8 x 8 DCT and JPEG-like quantisation for BSVTF tiles (seed 000 section 6: "a discrete cosine
// transformation (DCT) on 8 x 8 pixel blocks of the tile-images and then a quantization with
// respect to a quality threshold similar to JPEG ... our compression operates on floating point
// values").
//
// The DCT is the orthonormal 2D DCT-II (the one JPEG uses: DC = 8 x block mean), computed
// separably in double from a fixed cosine table, so encoder and decoder agree bit for bit on
// every platform with IEEE doubles.
//
// Quality -> quantisation steps (the IJG libjpeg rule, applied to float data):
//   S(q) = q < 50 ? 5000 / q : 200 - 2 q                       (q in 1..100)
//   step[k] = range / 255 * max(1, floor((Q50[k] * S(q) + 50) / 100))
// Q50 is the JPEG Annex K luminance table, `range` the value range (max - min) of the data being
// coded, so `range` plays the part of JPEG's 255: quality q quantises a float tile exactly as
// libjpeg quantises an 8-bit image at quality q. At q = 100 every step is range / 255
// (8-bit-like, not lossless); q = 50 uses Annex K's table as it is.
#pragma once
#include <array>
#include <cstdint>

namespace btfc::dct {

// k_zigzag[z] = natural (row-major, row = vertical frequency) index of zigzag position z.
extern const std::array<uint8_t, 64> k_zigzag;

// JPEG Annex K luminance quantisation table (quality 50), natural order.
extern const std::array<uint8_t, 64> k_jpeg_luma;

// Forward DCT of an 8 x 8 block read with row stride `stride` (floats); out: 64 coefficients,
// natural order.
void fdct8x8(const float* in, int stride, double out[64]);
// Inverse DCT of 64 natural-order coefficients into an 8 x 8 block with row stride `stride`.
void idct8x8(const double in[64], float* out, int stride);

// The 64 quantisation steps (natural order) for quality 1..100 and a value range > 0 (the rule
// above). Every step is > 0 for range > 0.
std::array<float, 64> quant_steps(int quality, float range);

}  // namespace btfc::dct
