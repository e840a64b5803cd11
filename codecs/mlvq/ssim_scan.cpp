// The codebook search's SSIM arithmetic (mlvq_internal.h, "SSIM of vectors"): the one-pair
// formula and the scan of one candidate against a run of entries, which leader_pass
// (codebook.cpp) runs for every candidate and entry of a level.
//
// Why a scan of its own: the search evaluates the SSIM of every (candidate, entry) pair from
// moments (a GEMM gives the dot products), and that evaluation, one call per pair with five
// double divisions, was a third of an mlvq encode (perf, the textile: 35 % in
// ssim_from_moments). The scan takes each entry's terms that do not depend on the candidate
// (se / n and see / n - me^2, EntryTerms) and each candidate's from outside the loop, and runs
// the rest over the entries in plain loops the compiler vectorizes (BTFC_CPU_CLONES: AVX-512,
// AVX2 or baseline, picked at load time).
//
// Same bits as ssim_from_moments for every pair: the hoisted terms are the same operations on
// the same values, each kept operation is the formula's own in its order, and this file is
// compiled with -ffp-contract=off (CMakeLists.txt) so that no clone fuses a multiply and an
// add (and with -fno-trapping-math, which changes no value: it lets the vectorizer evaluate
// both sides of the scale's select). So the scan changes none of the search's choices, on any
// CPU clone; tests/mlvq_test.cpp checks it against the formula pair by pair.
#include <algorithm>
#include <cstddef>

#include "codecs/mlvq/mlvq_internal.h"
#include "core/cpu_dispatch.h"

namespace btfc::mlvq {

double ssim_from_moments(double n, double sx, double sxx, double se, double see, double sxe, double L, bool scaled,
                         double* scale) {
  double s = 1;
  if (scaled) s = see > 0 ? std::max(0.0, sxe / see) : 0.0;
  if (scale) *scale = s;
  const double mx = sx / n, me = se / n;
  const double my = s * me;
  const double vx = std::max(0.0, sxx / n - mx * mx), vy = std::max(0.0, s * s * (see / n - me * me));
  const double cxy = s * (sxe / n - mx * me);
  const double c1 = (0.01 * L) * (0.01 * L), c2 = (0.03 * L) * (0.03 * L);
  if (c1 == 0 && c2 == 0) return 1;  // both vectors zero
  return ((2 * mx * my + c1) * (2 * cxy + c2)) / ((mx * mx + my * my + c1) * (vx + vy + c2));
}

void EntryTerms::add(double n_lum, double n_chroma, double se, double see, double sec, double seec) {
  const double me = n_lum > 0 ? se / n_lum : 0, mc = n_chroma > 0 ? sec / n_chroma : 0;
  see_l.push_back(see);
  me_l.push_back(me);
  q_l.push_back(n_lum > 0 ? see / n_lum - me * me : 0);
  me_c.push_back(mc);
  q_c.push_back(n_chroma > 0 ? seec / n_chroma - mc * mc : 0);
}

namespace {

// The candidate's side of the formula for one part: what ssim_from_moments computes before it
// looks at the entry.
struct Side {
  double n, mx, vx, c1, c2;
  bool zero_range;  // c1 == c2 == 0: the formula returns 1
};
Side side(double n, double sx, double sxx, double L) {
  Side s;
  s.n = n;
  s.mx = sx / n;
  s.vx = std::max(0.0, sxx / n - s.mx * s.mx);
  s.c1 = (0.01 * L) * (0.01 * L), s.c2 = (0.03 * L) * (0.03 * L);
  s.zero_range = s.c1 == 0 && s.c2 == 0;
  return s;
}

// Luminance (scaled) margins over k entries: margin[j] = SSIM - thr, scale[j] = s.
BTFC_CPU_CLONES void lum_margins(const Side c, const double* see, const double* me, const double* q, const float* g, size_t k,
                                 double thr, double* margin, double* scale) {
  const double n = c.n, mx = c.mx, vx = c.vx, c1 = c.c1, c2 = c.c2;
  for (size_t j = 0; j < k; ++j) {
    const double sxe = double(g[j]);
    // The formula's `see > 0 ? max(0, sxe / see) : 0` as a select of two computed values (this
    // file's -fno-trapping-math lets GCC evaluate the unused side's division and compare).
    const double st = std::max(0.0, sxe / see[j]);
    const double s = see[j] > 0 ? st : 0.0;
    const double my = s * me[j];
    const double vy = std::max(0.0, s * s * q[j]);
    const double cxy = s * (sxe / n - mx * me[j]);
    const double r = ((2 * mx * my + c1) * (2 * cxy + c2)) / ((mx * mx + my * my + c1) * (vx + vy + c2));
    margin[j] = r - thr;
    scale[j] = s;
  }
}

// Chromaticity (unscaled: s = 1, whose products are exact) margins, folded into margin[j] as
// std::min(margin[j], SSIM - thr), the search's order of operands.
BTFC_CPU_CLONES void chroma_margins(const Side c, const double* me, const double* q, const float* g, size_t k, double thr,
                                    double* margin) {
  const double n = c.n, mx = c.mx, vx = c.vx, c1 = c.c1, c2 = c.c2;
  for (size_t j = 0; j < k; ++j) {
    const double sxe = double(g[j]);
    const double my = me[j];
    const double vy = std::max(0.0, q[j]);
    const double cxy = sxe / n - mx * me[j];
    const double r = ((2 * mx * my + c1) * (2 * cxy + c2)) / ((mx * mx + my * my + c1) * (vx + vy + c2));
    margin[j] = std::min(margin[j], r - thr);
  }
}

}  // namespace

void ssim_margins(const ScanCandidate& x, const EntryTerms& e, size_t j0, size_t k, const float* gl, const float* gc, double* margin,
                  double* scale) {
  if (x.n_lum > 0) {
    const Side c = side(x.n_lum, x.sx, x.sxx, x.L);
    lum_margins(c, e.see_l.data() + j0, e.me_l.data() + j0, e.q_l.data() + j0, gl, k, x.thr_l, margin, scale);
    if (c.zero_range) std::fill(margin, margin + k, 1 - x.thr_l);
  } else {
    std::fill(margin, margin + k, 2.0);
    std::fill(scale, scale + k, 1.0);
  }
  if (x.n_chroma > 0) {
    const Side c = side(x.n_chroma, x.sxc, x.sxxc, 1.0);
    chroma_margins(c, e.me_c.data() + j0, e.q_c.data() + j0, gc, k, x.thr_c, margin);
  }
}

}  // namespace btfc::mlvq
