// fmf precision=q; see fmf_quant.h for the step rule.
#include "codecs/fmf/fmf_quant.h"

#include <algorithm>
#include <cmath>
#include <future>
#include <system_error>

#include "core/quant.h"

namespace btfc::fmf {

void quant_steps(const MatrixXfR& U, const MatrixXfR& SxV, int bits, std::vector<float>& u_steps, std::vector<float>& sxv_steps,
                 bool centred) {
  const Eigen::Index C = SxV.cols();
  // The header's D: the strongest eigen-texture's RMS, over at least U's rows / 16 texels.
  const double texels = quant::step_texels(double(SxV.rows()), double(U.rows()));
  std::vector<double> sigma(static_cast<size_t>(C), 0.0);
  double s1 = 0, s2 = 0;
  for (Eigen::Index k = 0; k < C; ++k) {
    const double sk = sigma[size_t(k)] = SxV.col(k).cast<double>().norm();
    if (sk > s1) s2 = s1, s1 = sk;
    else s2 = std::max(s2, sk);
  }
  if (centred && U.rows() > 0 && SxV.rows() > 0) {
    // The strongest component without the matrix's mean m (the header): the mean's energy
    // rows x texels x m^2 is at most s1^2 (a rank-1 part), so sqrt(s1^2 - it) is what the
    // strongest component varies by; the second-strongest bounds it below.
    const Eigen::VectorXd colsum_u = U.cast<double>().colwise().sum().transpose(), colsum_s = SxV.cast<double>().colwise().sum().transpose();
    const double rt = double(U.rows()) * double(SxV.rows()), m = colsum_u.dot(colsum_s) / rt;
    s1 = std::max(std::sqrt(std::max(0.0, s1 * s1 - rt * m * m)), s2);
  }
  double D = std::ldexp(s1 / std::sqrt(texels), -bits);
  if (!(D > 0) || !std::isfinite(D)) D = 1;  // all-zero factors: any step codes them exactly
  u_steps.resize(size_t(C)), sxv_steps.resize(size_t(C));
  for (Eigen::Index k = 0; k < C; ++k) {
    const double sk = sigma[size_t(k)];
    // A component with sigma_k = 0 contributes nothing: a step of 4 rounds its |U| <= 1 to 0.
    const double dk = sk > 0 ? std::min(4.0, D / sk) : 4.0;
    u_steps[size_t(k)] = quant::safe_step(dk, U.rows() ? double(U.col(k).cwiseAbs().maxCoeff()) : 0.0);
    sxv_steps[size_t(k)] = quant::safe_step(D, SxV.rows() ? double(SxV.col(k).cwiseAbs().maxCoeff()) : 0.0);
  }
}

QuantizedFactors quantize_factors(const std::string& name, const MatrixXfR& U, const MatrixXfR& SxV, const QuantConfig& cfg, int width,
                                  int height) {
  QuantizedFactors out;
  std::vector<float> us, ss;
  quant_steps(U, SxV, cfg.bits, us, ss, cfg.centred);
  const uint64_t C = uint64_t(U.cols());
  quant::Layout L;
  if (cfg.dct) L.dct = true, L.width = uint32_t(width), L.height = uint32_t(height);
  // The two tensors on two threads: each quant::encode is one zstd (level 19) call, most of an
  // encode's time after the SVD (30 % of a `--max-bytes` search's on the textile, perf), and the
  // other core idled through it. Same bytes either way. (A tensor of 8 MiB of planes or more is
  // itself two zstd jobs on two workers, core/quant.h: U at ranks in the hundreds.)
  std::vector<float> deq_u, deq_s;
  auto encode_s = [&] { return quant::encode("SxV." + name, {uint64_t(SxV.rows()), C}, SxV.data(), ss, L, 19, &deq_s); };
  std::future<Result<Tensor>> pending;
  try {
    pending = std::async(std::launch::async, encode_s);
  } catch (const std::system_error&) {  // no thread to be had: one after the other
  }
  auto coded_u = quant::encode("U." + name, {uint64_t(U.rows()), C}, U.data(), us, {}, 19, &deq_u);
  auto coded_s = pending.valid() ? pending.get() : encode_s();
  if (!coded_u.ok()) return out.status = coded_u.status(), out.U = U, out.SxV = SxV, out;
  if (!coded_s.ok()) return out.status = coded_s.status(), out.U = U, out.SxV = SxV, out;
  out.U = Eigen::Map<MatrixXfR>(deq_u.data(), U.rows(), U.cols());
  out.SxV = Eigen::Map<MatrixXfR>(deq_s.data(), SxV.rows(), SxV.cols());
  out.coded.push_back(std::move(coded_u).value());
  out.coded.push_back(std::move(coded_s).value());
  return out;
}

}  // namespace btfc::fmf
