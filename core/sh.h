// Real spherical harmonics for the lpca codec (seed 002 section 4.2): basis evaluation,
// projection by quadrature (over measured light directions or a dense sphere grid), rotation.
//
// Conventions (used by every lpca function):
//  - Real, orthonormal SH on the unit sphere: integral y_i y_j dw = delta_ij. Index
//    j = l*l + l + m for band l = 0..n-1, m = -l..l. "Order n" means bands 0..n-1, n*n
//    coefficients (the paper's "n-th order, n^2 coefficients"; default n = 5 -> 25).
//    y_l0 = K_l0 P_l(cos theta); m > 0: sqrt2 K_lm cos(m phi) P_l^m; m < 0: sqrt2 K_l|m| sin(|m| phi) P_l^|m|,
//    with the Condon-Shortley phase inside P_l^m. theta from +z, phi = atan2(y, x).
//  - A rotation R acts on functions by (R f)(d) = f(R^T d): rotating a lighting environment by R
//    moves the light that came from d to R d.
#pragma once
#include <array>
#include <functional>
#include <vector>

#include "core/btf.h"
#include "core/status.h"

namespace btfc::sh {

constexpr int k_max_order = 16;  // bands 0..15, 256 coefficients

// 3 x 3 rotation, row-major: (R d)_i = sum_j m[i][j] d_j.
struct Mat3 {
  double m[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  static Mat3 identity() { return {}; }
  // Rotation by `angle` radians about the (normalized) `axis`, right-handed.
  static Mat3 axis_angle(double ax, double ay, double az, double angle);
  Mat3 transpose() const;
  Mat3 operator*(const Mat3& o) const;
  void apply(const double in[3], double out[3]) const;
};

inline int num_coeffs(int order) { return order * order; }

// All n*n basis values at the unit direction (x, y, z) (need not be exactly unit: it is normalized).
void eval_basis(int order, double x, double y, double z, double* out);

// Quadrature weights over a measured direction set: the solid angle of each direction's
// spherical Voronoi cell within the upper hemisphere (z >= 0), estimated by assigning the cells of
// an equal-area grid (cos theta x phi, `resolution` x 4*`resolution` cells, each 2 pi / (4 res^2)
// sr) to the nearest direction (largest dot product). The weights sum to 2 pi, so a quadrature
// sum_i w_i f(d_i) integrates f over the whole hemisphere: cells of the outermost ring (UBO2003:
// theta = 75 deg) extend to the horizon. Ties go to the lower index; an empty set gives {}.
std::vector<double> hemisphere_cell_weights(const DirectionSet& dirs, int resolution = 256);

// Projection of samples f_i at directions d_i with weights w_i: c_j = sum_i w_i f_i y_j(d_i).
// `values` is [count][stride] with `channels` values at the start of each row; the result is
// [channels][n*n] (channel-major).
std::vector<double> project_samples(int order, const std::vector<Vec3>& dirs, const std::vector<double>& weights,
                                    const float* values, size_t stride, int channels);

// Dense projection of a function over the whole sphere: Gauss-Legendre in cos theta (`resolution`
// nodes on each of [-1, 0] and [0, 1]) x 2*`resolution` uniform phi. Exact (to round-off) for
// integrands polynomial in cos theta on each hemisphere up to degree 2*resolution - 1 and
// trigonometric in phi; for tests, analytic references and smooth procedural environments.
std::vector<double> project_function(int order, const std::function<double(double, double, double)>& f, int resolution = 64);

// Coefficients of the rotated function d -> f(R^T d), one channel of n*n coefficients.
// Exact for band-limited functions (rotation mixes coefficients only within a band); each band's
// (2l+1)^2 matrix is found by fitting the rotated basis on 4l+3 quasi-uniform directions
// (least squares, double precision; error ~1e-13).
std::vector<double> rotate(int order, const double* coeffs, const Mat3& R);

// Value of an expansion at a direction: sum_j c_j y_j(d).
double evaluate(int order, const double* coeffs, double x, double y, double z);

}  // namespace btfc::sh

namespace btfc {

// SH expansion of an RGB lighting environment: order n (bands 0..n-1), coefficients [3][n*n].
struct EnvironmentSH {
  int order = 0;
  std::vector<double> coeffs;
};

// Projects a lat-long RGB float image (row-major, 3 floats per pixel, layout above) onto SH by
// exact per-pixel solid angles. Errors: non-positive size, order outside [1, 16], NaN/Inf pixels.
Result<EnvironmentSH> project_latlong(const float* rgb, int width, int height, int order);
// The environment rotated by R (light arriving from d now arrives from R d).
EnvironmentSH rotate_environment(const EnvironmentSH& env, const sh::Mat3& R);

}  // namespace btfc
