// Real spherical harmonics; see sh.h for the conventions.
#include "core/sh.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>

namespace btfc::sh {
namespace {

constexpr double k_pi = 3.14159265358979323846;

// K_lm = sqrt((2l+1)/(4 pi) (l-m)!/(l+m)!), tabulated once for all bands.
struct NormTable {
  double k[k_max_order][k_max_order];
  NormTable() {
    for (int l = 0; l < k_max_order; ++l)
      for (int m = 0; m <= l; ++m) {
        double ratio = 1;  // (l-m)!/(l+m)!
        for (int i = l - m + 1; i <= l + m; ++i) ratio /= i;
        k[l][m] = std::sqrt((2 * l + 1) / (4 * k_pi) * ratio);
      }
  }
};
const NormTable k_norm;

}  // namespace

Mat3 Mat3::axis_angle(double ax, double ay, double az, double angle) {
  const double n = std::sqrt(ax * ax + ay * ay + az * az);
  ax /= n, ay /= n, az /= n;
  const double c = std::cos(angle), s = std::sin(angle), t = 1 - c;
  Mat3 r;
  r.m[0][0] = t * ax * ax + c, r.m[0][1] = t * ax * ay - s * az, r.m[0][2] = t * ax * az + s * ay;
  r.m[1][0] = t * ax * ay + s * az, r.m[1][1] = t * ay * ay + c, r.m[1][2] = t * ay * az - s * ax;
  r.m[2][0] = t * ax * az - s * ay, r.m[2][1] = t * ay * az + s * ax, r.m[2][2] = t * az * az + c;
  return r;
}

Mat3 Mat3::transpose() const {
  Mat3 r;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) r.m[i][j] = m[j][i];
  return r;
}

Mat3 Mat3::operator*(const Mat3& o) const {
  Mat3 r;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) r.m[i][j] = m[i][0] * o.m[0][j] + m[i][1] * o.m[1][j] + m[i][2] * o.m[2][j];
  return r;
}

void Mat3::apply(const double in[3], double out[3]) const {
  for (int i = 0; i < 3; ++i) out[i] = m[i][0] * in[0] + m[i][1] * in[1] + m[i][2] * in[2];
}

void eval_basis(int order, double x, double y, double z, double* out) {
  const double len = std::sqrt(x * x + y * y + z * z);
  if (len > 0) x /= len, y /= len, z /= len;
  const double ct = std::clamp(z, -1.0, 1.0), st = std::sqrt(std::max(0.0, 1 - ct * ct));
  const double phi = std::atan2(y, x);
  // P_l^m(ct) by the standard recurrences, column by column in m.
  double P[k_max_order][k_max_order];
  double pmm = 1;
  for (int m = 0; m < order; ++m) {
    if (m > 0) pmm *= -(2 * m - 1) * st;
    P[m][m] = pmm;
    if (m + 1 < order) P[m + 1][m] = ct * (2 * m + 1) * pmm;
    for (int l = m + 2; l < order; ++l) P[l][m] = ((2 * l - 1) * ct * P[l - 1][m] - (l + m - 1) * P[l - 2][m]) / (l - m);
  }
  const double sqrt2 = std::sqrt(2.0);
  for (int l = 0; l < order; ++l) {
    const int base = l * l + l;
    out[base] = k_norm.k[l][0] * P[l][0];
    for (int m = 1; m <= l; ++m) {
      const double v = sqrt2 * k_norm.k[l][m] * P[l][m];
      out[base + m] = v * std::cos(m * phi);
      out[base - m] = v * std::sin(m * phi);
    }
  }
}

double evaluate(int order, const double* coeffs, double x, double y, double z) {
  double y_buf[k_max_order * k_max_order];
  eval_basis(order, x, y, z, y_buf);
  double s = 0;
  for (int j = 0; j < order * order; ++j) s += coeffs[j] * y_buf[j];
  return s;
}

std::vector<double> hemisphere_cell_weights(const DirectionSet& dirs, int resolution) {
  const int n = int(dirs.size());
  if (n == 0) return {};
  const int nu = resolution, nphi = 4 * resolution;
  const double cell = 2 * k_pi / (double(nu) * nphi);  // (1/nu) in cos theta x (2 pi / nphi) in phi
  std::vector<double> w(size_t(n), 0.0);
#pragma omp parallel
  {
    std::vector<double> local(size_t(n), 0.0);
#pragma omp for schedule(static)
    for (int iu = 0; iu < nu; ++iu) {
      const double ct = (iu + 0.5) / nu, st = std::sqrt(1 - ct * ct);
      for (int ip = 0; ip < nphi; ++ip) {
        const double phi = 2 * k_pi * (ip + 0.5) / nphi;
        const double x = st * std::cos(phi), y = st * std::sin(phi);
        int best = 0;
        double best_dot = -2;
        for (int i = 0; i < n; ++i) {
          const Vec3& d = dirs.dirs[size_t(i)];
          const double dot = x * d.x + y * d.y + ct * d.z;
          if (dot > best_dot) best_dot = dot, best = i;
        }
        local[size_t(best)] += cell;
      }
    }
#pragma omp critical
    for (int i = 0; i < n; ++i) w[size_t(i)] += local[size_t(i)];
  }
  return w;
}

std::vector<double> project_samples(int order, const std::vector<Vec3>& dirs, const std::vector<double>& weights,
                                    const float* values, size_t stride, int channels) {
  const int nc = order * order;
  std::vector<double> out(size_t(channels) * nc, 0.0);
  double y_buf[k_max_order * k_max_order];
  for (size_t i = 0; i < dirs.size(); ++i) {
    eval_basis(order, dirs[i].x, dirs[i].y, dirs[i].z, y_buf);
    for (int c = 0; c < channels; ++c) {
      const double f = weights[i] * values[i * stride + size_t(c)];
      for (int j = 0; j < nc; ++j) out[size_t(c) * nc + j] += f * y_buf[j];
    }
  }
  return out;
}

std::vector<double> project_function(int order, const std::function<double(double, double, double)>& f, int resolution) {
  // Gauss-Legendre nodes in cos theta, separately on [-1, 0] and [0, 1] (so functions with a kink
  // at the horizon, like a clamped cosine, are still integrated exactly when polynomial on each
  // half), and uniform phi (exact for trigonometric polynomials of degree < 2 * resolution).
  const int n = resolution, nc = order * order, nphi = 2 * resolution;
  std::vector<double> gx(static_cast<size_t>(n)), gw(static_cast<size_t>(n));
  for (int i = 0; i < n; ++i) {  // Newton on P_n from the Chebyshev-like initial guess
    double x = std::cos(k_pi * (i + 0.75) / (n + 0.5)), dp = 1;
    for (int it = 0; it < 100; ++it) {
      double p0 = 1, p1 = x;
      for (int k = 2; k <= n; ++k) {
        const double p2 = ((2 * k - 1) * x * p1 - (k - 1) * p0) / k;
        p0 = p1, p1 = p2;
      }
      dp = n * (x * p1 - p0) / (x * x - 1);
      const double dx = p1 / dp;
      x -= dx;
      if (std::abs(dx) < 1e-16) break;
    }
    gx[size_t(i)] = x;
    gw[size_t(i)] = 2 / ((1 - x * x) * dp * dp);
  }
  std::vector<double> out(size_t(nc), 0.0);
  double y_buf[k_max_order * k_max_order];
  for (int half = 0; half < 2; ++half)
    for (int i = 0; i < n; ++i) {
      const double ct = (gx[size_t(i)] + (half ? 1 : -1)) / 2, st = std::sqrt(std::max(0.0, 1 - ct * ct));
      const double w = gw[size_t(i)] / 2 * (2 * k_pi / nphi);
      for (int ip = 0; ip < nphi; ++ip) {
        const double phi = 2 * k_pi * (ip + 0.5) / nphi;
        const double x = st * std::cos(phi), y = st * std::sin(phi);
        const double v = f(x, y, ct) * w;
        if (v == 0) continue;
        eval_basis(order, x, y, ct, y_buf);
        for (int j = 0; j < nc; ++j) out[size_t(j)] += v * y_buf[j];
      }
    }
  return out;
}

std::vector<double> rotate(int order, const double* coeffs, const Mat3& R) {
  std::vector<double> out(size_t(order) * order, 0.0);
  const Mat3 Rt = R.transpose();
  double y_buf[k_max_order * k_max_order];
  for (int l = 0; l < order; ++l) {
    const int dim = 2 * l + 1, npts = 4 * l + 3, base = l * l;
    Eigen::MatrixXd A(npts, dim), B(npts, dim);
    for (int i = 0; i < npts; ++i) {
      // Fibonacci sphere: quasi-uniform, so the least-squares fit is well conditioned.
      const double z = 1 - 2 * (i + 0.5) / npts, r = std::sqrt(std::max(0.0, 1 - z * z));
      const double phi = i * k_pi * (3 - std::sqrt(5.0));
      const double d[3] = {r * std::cos(phi), r * std::sin(phi), z};
      double rd[3];
      Rt.apply(d, rd);
      eval_basis(l + 1, d[0], d[1], d[2], y_buf);
      for (int j = 0; j < dim; ++j) A(i, j) = y_buf[base + j];
      eval_basis(l + 1, rd[0], rd[1], rd[2], y_buf);
      for (int j = 0; j < dim; ++j) B(i, j) = y_buf[base + j];
    }
    // y_l(R^T d) = D y_l(d) for every d, so B = A D^T; the rotated coefficients are D^T c.
    const Eigen::MatrixXd Dt = A.colPivHouseholderQr().solve(B);
    const Eigen::Map<const Eigen::VectorXd> c(coeffs + base, dim);
    Eigen::Map<Eigen::VectorXd>(out.data() + base, dim) = Dt * c;
  }
  return out;
}

}  // namespace btfc::sh

namespace btfc {
namespace {
constexpr double k_pi = 3.14159265358979323846;
}  // namespace

Result<EnvironmentSH> project_latlong(const float* rgb, int width, int height, int order) {
  if (width <= 0 || height <= 0 || size_t(width) * size_t(height) > (size_t(1) << 28))
    return invalid_argument("environment: bad lat-long size " + std::to_string(width) + "x" + std::to_string(height));
  if (order < 1 || order > sh::k_max_order) return invalid_argument("environment: SH order " + std::to_string(order) + " outside [1, 16]");
  const int n2 = sh::num_coeffs(order);
  EnvironmentSH env;
  env.order = order;
  env.coeffs.assign(size_t(3) * size_t(n2), 0.0);
  bool finite = true;
#pragma omp parallel
  {
    std::vector<double> acc(env.coeffs.size(), 0.0), y(static_cast<size_t>(n2));
#pragma omp for schedule(static) reduction(&& : finite)
    for (int j = 0; j < height; ++j) {
      // Exact solid angle of the pixel row's cells; the basis is taken at the cell centre.
      const double dw = 2 * k_pi / width * (std::cos(k_pi * j / height) - std::cos(k_pi * (j + 1) / height));
      const double th = k_pi * (j + 0.5) / height, st = std::sin(th), ct = std::cos(th);
      for (int i = 0; i < width; ++i) {
        const double ph = 2 * k_pi * (i + 0.5) / width;
        const float* px = rgb + (size_t(j) * size_t(width) + size_t(i)) * 3;
        if (!std::isfinite(px[0]) || !std::isfinite(px[1]) || !std::isfinite(px[2])) finite = false;
        if (px[0] == 0 && px[1] == 0 && px[2] == 0) continue;
        sh::eval_basis(order, st * std::cos(ph), st * std::sin(ph), ct, y.data());
        for (int c = 0; c < 3; ++c) {
          const double f = dw * px[c];
          for (int k = 0; k < n2; ++k) acc[size_t(c) * size_t(n2) + size_t(k)] += f * y[size_t(k)];
        }
      }
    }
#pragma omp critical
    for (size_t k = 0; k < acc.size(); ++k) env.coeffs[k] += acc[k];
  }
  if (!finite) return invalid_argument("environment: NaN or Inf pixel values");
  return env;
}

EnvironmentSH rotate_environment(const EnvironmentSH& env, const sh::Mat3& R) {
  EnvironmentSH out;
  out.order = env.order;
  const size_t n2 = size_t(sh::num_coeffs(env.order));
  for (int c = 0; c < 3; ++c) {
    if (env.coeffs.size() < (size_t(c) + 1) * n2) break;
    std::vector<double> r = sh::rotate(env.order, env.coeffs.data() + size_t(c) * n2, R);
    out.coeffs.insert(out.coeffs.end(), r.begin(), r.end());
  }
  return out;
}

}  // namespace btfc
