// lpyr: Phong fit of the top-level Y mean (paper section 3.2, eq. 5) by Levenberg-Marquardt:
// Ceres 2.1 when btfc is built with it, else a projected LM of our own (4 parameters, analytic
// Jacobian; Ceres is an optional dependency). Contract in lpyr_internal.h.
#ifdef BTFC_HAVE_CERES
#include <ceres/ceres.h>
#endif

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>

#include "codecs/lpyr/lpyr_internal.h"

namespace btfc::lpyr {
namespace {

constexpr double k_alpha_min = 1, k_alpha_max = 1000;
constexpr double k_nh_floor = 1e-12;  // keeps log(N.H) finite for the alpha derivative

struct Sample {
  double nl, log_nh;
};

double clamp01(double x) { return x < 0 ? 0 : (x > 1 ? 1 : x); }

Sample sample_of(const Vec3& l, const Vec3& v) {
  const double hx = double(l.x) + v.x, hy = double(l.y) + v.y, hz = double(l.z) + v.z;
  const double n = std::sqrt(hx * hx + hy * hy + hz * hz);
  const double nh = n > 0 ? clamp01(hz / n) : 0;
  return {clamp01(l.z), std::log(std::max(nh, k_nh_floor))};
}

#ifdef BTFC_HAVE_CERES
// One residual per (light, view) sample; x = (ka, kd, ks, alpha).
struct Residual {
  Sample s;
  double target;
  template <class T>
  bool operator()(const T* x, T* r) const {
    r[0] = x[0] + x[1] * s.nl + x[2] * exp(x[3] * s.log_nh) - target;
    return true;
  }
};
#endif

double sse(const std::vector<Sample>& s, const std::vector<double>& y, const double* x) {
  double e = 0;
  for (size_t i = 0; i < s.size(); ++i) {
    const double r = x[0] + x[1] * s[i].nl + x[2] * std::exp(x[3] * s[i].log_nh) - y[i];
    e += r * r;
  }
  return e;
}

// Bounded linear least squares for (ka free, kd >= 0, ks >= 0) at a fixed alpha: the
// unconstrained solution if feasible, else the best feasible solution of the smaller active
// sets (3 unknowns: enumerating the 4 subsets is exact and cheap).
void linear_fit(const std::vector<Sample>& s, const std::vector<double>& y, double alpha, double* x) {
  const Eigen::Index n = Eigen::Index(s.size());
  Eigen::MatrixXd A(n, 3);
  Eigen::VectorXd b(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    A(i, 0) = 1, A(i, 1) = s[size_t(i)].nl, A(i, 2) = std::exp(alpha * s[size_t(i)].log_nh);
    b(i) = y[size_t(i)];
  }
  double best = INFINITY;
  for (int mask : {3, 1, 2, 0}) {  // bit 0: kd free, bit 1: ks free
    std::vector<Eigen::Index> cols{0};
    if (mask & 1) cols.push_back(1);
    if (mask & 2) cols.push_back(2);
    Eigen::MatrixXd As(n, Eigen::Index(cols.size()));
    for (size_t c = 0; c < cols.size(); ++c) As.col(Eigen::Index(c)) = A.col(cols[c]);
    const Eigen::VectorXd z = As.colPivHouseholderQr().solve(b);
    double cand[4] = {0, 0, 0, alpha};
    for (size_t c = 0; c < cols.size(); ++c) cand[cols[c]] = z(Eigen::Index(c));
    if (cand[1] < 0 || cand[2] < 0 || !std::isfinite(cand[0] + cand[1] + cand[2])) continue;
    const double e = sse(s, y, cand);
    if (e < best) best = e, std::copy(cand, cand + 4, x);
  }
}

void clamp_bounds(double* x) {
  x[1] = std::max(x[1], 0.0), x[2] = std::max(x[2], 0.0), x[3] = std::clamp(x[3], k_alpha_min, k_alpha_max);
}

// Projected Levenberg-Marquardt (Marquardt's diagonal scaling, steps projected onto the bounds;
// accepted only when they lower the sum of squares). Returns the iterations taken.
int projected_lm(const std::vector<Sample>& s, const std::vector<double>& y, double* x) {
  double lambda = 1e-3, e = sse(s, y, x);
  int it = 0;
  for (; it < 200; ++it) {
    Eigen::Matrix4d JtJ = Eigen::Matrix4d::Zero();
    Eigen::Vector4d Jtr = Eigen::Vector4d::Zero();
    for (size_t i = 0; i < s.size(); ++i) {
      const double ex = std::exp(x[3] * s[i].log_nh);
      const double r = x[0] + x[1] * s[i].nl + x[2] * ex - y[i];
      const Eigen::Vector4d J(1.0, s[i].nl, ex, x[2] * s[i].log_nh * ex);
      JtJ += J * J.transpose();
      Jtr += J * r;
    }
    bool accepted = false;
    while (lambda < 1e16) {
      Eigen::Matrix4d A = JtJ;
      for (int k = 0; k < 4; ++k) A(k, k) += lambda * std::max(JtJ(k, k), 1e-12);
      const Eigen::Vector4d step = A.ldlt().solve(-Jtr);
      double cand[4] = {x[0] + step(0), x[1] + step(1), x[2] + step(2), x[3] + step(3)};
      clamp_bounds(cand);
      const double ec = sse(s, y, cand);
      if (std::isfinite(ec) && ec < e) {
        const double gain = e - ec;
        std::copy(cand, cand + 4, x);
        e = ec, lambda = std::max(lambda / 3, 1e-12), accepted = true;
        if (gain <= 1e-14 * std::max(e, 1e-300)) return it + 1;
        break;
      }
      lambda *= 4;
    }
    if (!accepted) break;  // no step lowers the error: a (bounded) minimum
  }
  return it;
}

}  // namespace

bool have_ceres() {
#ifdef BTFC_HAVE_CERES
  return true;
#else
  return false;
#endif
}

double phong_eval(const Phong& p, const Vec3& l, const Vec3& v) {
  const Sample s = sample_of(l, v);
  return double(p.ka) + double(p.kd) * s.nl + double(p.ks) * std::exp(double(p.alpha) * s.log_nh);
}

PhongFit fit_phong(const DirectionSet& lights, const DirectionSet& views, const double* mu, PhongSolver solver) {
  const size_t nl = lights.size(), n = nl * views.size();
  PhongFit fit;
  double scale = 0, norm2 = 0;
  for (size_t i = 0; i < n; ++i) scale = std::max(scale, std::abs(mu[i])), norm2 += mu[i] * mu[i];
  auto finish = [&](double ka, double kd, double ks, double alpha) {
    fit.p = {float(ka * scale), float(kd * scale), float(ks * scale), float(alpha)};
    double e = 0;
    for (size_t r = 0; r < n; ++r) {
      const double d = phong_eval(fit.p, lights.dirs[r % nl], views.dirs[r / nl]) - mu[r];
      e += d * d;
    }
    fit.rms_residual = n ? std::sqrt(e / double(n)) : 0;
    fit.rel_residual = norm2 > 0 ? std::sqrt(e / norm2) : 0;
    return fit;
  };
  if (!(scale > 0) || !std::isfinite(scale)) {
    fit.method = "zero";
    scale = 0;
    return finish(0, 0, 0, 1);
  }
  std::vector<Sample> s(n);
  std::vector<double> y(n);
  double mean = 0;
  for (size_t r = 0; r < n; ++r) {
    s[r] = sample_of(lights.dirs[r % nl], views.dirs[r / nl]);
    y[r] = mu[r] / scale;
    mean += y[r] / double(n);
  }
  if (n < 4) {  // fewer samples than parameters: the constant is the honest answer
    fit.method = "constant";
    return finish(mean, 0, 0, 1);
  }
  // Start: the best bounded linear fit over a log grid of alpha (LM alone can stall in the
  // flat region of alpha when ks starts near 0).
  double x[4] = {mean, 0, 0, 1}, best = sse(s, y, x);
  for (int i = 0; i <= 30; ++i) {
    double cand[4] = {mean, 0, 0, 1};
    linear_fit(s, y, std::pow(k_alpha_max, double(i) / 30.0), cand);
    const double e = sse(s, y, cand);
    if (e < best) best = e, std::copy(cand, cand + 4, x);
  }
  double start[4];
  std::copy(x, x + 4, start);

  const bool use_ceres = solver != PhongSolver::projected && have_ceres();
  if (!use_ceres) {
    fit.iterations = projected_lm(s, y, x);
    fit.method = "lm-projected";
  }
#ifdef BTFC_HAVE_CERES
  if (use_ceres) {
    ceres::Problem problem;
    for (size_t r = 0; r < n; ++r)
      problem.AddResidualBlock(new ceres::AutoDiffCostFunction<Residual, 1, 4>(new Residual{s[r], y[r]}), nullptr, x);
    problem.SetParameterLowerBound(x, 1, 0);
    problem.SetParameterLowerBound(x, 2, 0);
    problem.SetParameterLowerBound(x, 3, k_alpha_min);
    problem.SetParameterUpperBound(x, 3, k_alpha_max);
    ceres::Solver::Options opt;
    opt.minimizer_type = ceres::TRUST_REGION;
    opt.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
    opt.linear_solver_type = ceres::DENSE_QR;
    opt.max_num_iterations = 200;
    opt.function_tolerance = 1e-12;
    opt.parameter_tolerance = 1e-12;
    opt.logging_type = ceres::SILENT;
    opt.minimizer_progress_to_stdout = false;
    ceres::Solver::Summary summary;
    ceres::Solve(opt, &problem, &summary);
    fit.iterations = int(summary.iterations.size());
    fit.method = "lm";
  }
#endif
  const bool finite = std::isfinite(x[0]) && std::isfinite(x[1]) && std::isfinite(x[2]) && std::isfinite(x[3]);
  if (!finite || sse(s, y, x) > best) std::copy(start, start + 4, x);
  return finish(x[0], x[1], x[2], std::clamp(x[3], k_alpha_min, k_alpha_max));
}

}  // namespace btfc::lpyr
