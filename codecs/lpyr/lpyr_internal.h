// Internal pieces of the lpyr codec, shared by its .cpp files and tests/lpyr_test.cpp.
// Not part of btfc's public API; codecs/lpyr/lpyr.h is the contract.
#pragma once
#include <Eigen/Core>
#include <string>
#include <vector>

#include "codecs/codec.h"
#include "core/interp.h"

namespace btfc::lpyr {

using MatrixXfR = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

enum Channel { k_y = 0, k_cb = 1, k_cr = 2 };
extern const char* const k_channel_names[3];  // "y", "cb", "cr"

// ---- colour (pyramid.cpp) ---------------------------------------------------------------------
// ITU-R BT.601 full range (Kr = 0.299, Kb = 0.114), applied to the *linear* values btfc holds,
// without the +0.5 chroma offset (data are float; an offset would only move the means).
// Y in the data's units; Cb = (B - Y) / (2 (1 - Kb)), Cr = (R - Y) / (2 (1 - Kr)).
// The inverse is exact (derived from the same Kr, Kb), so RGB -> YCbCr -> RGB is lossless to
// float round-off.
void rgb_to_ycbcr(const float* rgb, float* ycc);
void ycbcr_to_rgb(const float* ycc, float* rgb);

// ---- pyramid (pyramid.cpp) -----------------------------------------------------------------
// Level k has size w_k x h_k with w_{k+1} = ceil(w_k / 2) (odd sizes keep their last column).
struct LevelSize {
  int w = 0, h = 0;
  size_t texels() const { return size_t(w) * size_t(h); }
};
std::vector<LevelSize> level_sizes(int width, int height, int lmax);
// First k with w_k = h_k = 1 (more levels would only repeat 1x1 images).
int max_lmax(int width, int height);
// The paper's stopping rule: the smallest k whose level has <= 2 * components texels
// ("about as many Laplacian BRDFs as components"), capped by max_lmax.
int auto_lmax(int width, int height, int components);
// Levels from the bytes (lpyr.h "Levels from the data"): the largest k (capped by max_lmax)
// such that every level j <= k has d <= ratio * N_j (its bases, d values per component, cost at
// most `ratio` times its weights, N_j per component); 0 when even level 0 fails.
int bytes_lmax(int width, int height, size_t d, int ratio);

// The pyramid operators on texel-major stacks: `d` floats per texel (one value per (light, view)
// pair of one channel), texel t = x + w * y. All images of a level are filtered at once, so the
// inner loops run over contiguous direction vectors.
//  reduce:   F_{k+1}(i, j) = box3(F_k)(2i, 2j), the 3x3 box mean with clamped (replicated)
//            borders; dst holds ceil(w/2) * ceil(h/2) texels.
//  subtract_up: F_k(x, y) -= F_{k+1}(x / 2, y / 2)   (nearest-neighbour up-sampling, cropped to
//            w x h), turning F_k into the Laplacian L_k in place.
void reduce(const float* src, int w, int h, size_t d, float* dst);
void subtract_up(float* f, int w, int h, size_t d, const float* next);

// ---- Phong fit (phong_fit.cpp) --------------------------------------------------------------
// mu(l, v) = ka + kd (N.L) + ks (N.H)^alpha with N = (0, 0, 1), H = normalize(L + V),
// N.L and N.H clamped to [0, 1].
struct Phong {
  float ka = 0, kd = 0, ks = 0, alpha = 1;
};
double phong_eval(const Phong& p, const Vec3& l, const Vec3& v);

struct PhongFit {
  Phong p;
  double rms_residual = 0;  // sqrt(mean (mu - fit)^2)
  double rel_residual = 0;  // ||mu - fit|| / ||mu|| (0 for all-zero mu)
  int iterations = 0;       // LM iterations (0 when no LM was needed)
  std::string method;       // "lm" (Ceres), "lm-projected" (btfc's own), "constant" (fewer than 4 samples) or "zero"
};
// The LM that refines the start: Ceres's (when btfc was built with it, BTFC_HAVE_CERES) or a
// projected Levenberg-Marquardt of btfc's own (the fallback when Ceres is absent; both reach the
// same minimum on the tests' data, tests/lpyr_test.cpp). `automatic`: Ceres when built with it.
enum class PhongSolver { automatic, ceres, projected };
bool have_ceres();
// Fits mu[r], r = l + lights.size() * v, over every (light, view) pair. Levenberg-Marquardt
// (Ceres) with kd, ks >= 0 and alpha in [1, 1000], on data divided by max |mu| (so HDR scales
// from 1e-6 to 1e6 condition the same), started from the best of a grid over alpha solved by
// bounded linear least squares. Never fails: all-zero data give all-zero coefficients, fewer
// than 4 samples give the constant mean; a non-finite LM result falls back to the start.
// `ceres` without Ceres in the build falls back to `projected` (method says which ran).
PhongFit fit_phong(const DirectionSet& lights, const DirectionSet& views, const double* mu, PhongSolver solver = PhongSolver::automatic);

// ---- model (lpyr_model.cpp) -----------------------------------------------------------------
// One PCA block: a level's channel. Reconstruction of texel t, direction row r:
//   L(t, r) ~ D.row(t) . E.row(r) + mean(r)    (mean empty = dropped)
struct Block {
  MatrixXfR E;           // d x C eigen-Laplacian-BRDFs (orthonormal columns before rounding)
  MatrixXfR D;           // N_k x C PCA weights, dequantized
  Eigen::VectorXf scale; // C, per-component storage scale of D
  Eigen::VectorXf mean;  // d or empty
  std::vector<Tensor> coded;  // precision=q: zq tensors E.<k>.<ch>, D.<k>.<ch> [, mean.<k>.<ch>] as saved
};
struct Level {
  LevelSize size;
  Block ch[3];
  bool mean_stored[3] = {false, false, false};  // a mean vector is stored in the file
};

struct Config {
  bool half = true;
  int bits = 0;  // precision=q: > 0
};

class LpyrModel final : public Model {
 public:
  // levels.back() is the top; when `phong` is set its Y mean is the Phong function and its
  // Cb/Cr means the constants chroma[0..1] (filled into the top blocks' mean vectors here).
  LpyrModel(BtfDesc desc, std::string spec, Config cfg, std::vector<Level> levels, bool phong, Phong ph, float chroma[2]);

  const BtfDesc& desc() const override { return m_desc; }
  const std::string& spec() const override { return m_spec; }
  int lmax() const { return int(m_levels.size()) - 1; }
  const std::vector<Level>& levels() const { return m_levels; }
  bool uses_phong() const { return m_phong; }
  const Phong& phong() const { return m_ph; }
  ModelStats& mutable_stats() { return m_stats; }

  Status decode(const DecodeRequest& req, Btf& out) const override;
  void eval(int x, int y, int light, int view, float* out) const override;
  Status eval_dir(int x, int y, const Vec3& wl, const Vec3& wv, float* out) const override;
  // eval / eval_dir's values (to float round-off: the pairs blended in YCbCr, then one
  // conversion), without their per-call overheads: lpyr_model.cpp says why.
  Status eval_batch(std::span<const EvalQuery> q, float* out) const override;
  Status eval_lod(int x, int y, int light, int view, double lod, float* out) const override;
  Result<std::vector<Tensor>> gpu_tensors() const override;
  Status save(ContainerWriter& w) const override;
  uint64_t payload_bytes() const override;
  ModelStats stats() const override { return m_stats; }

  static Result<std::unique_ptr<Model>> load(const ContainerReader& rd, Params p);

 private:
  void eval_ycc(int x, int y, size_t row, double lod, float* ycc) const;
  Status check_lod(double lod) const;

  BtfDesc m_desc;
  std::string m_spec;
  Config m_cfg;
  std::vector<Level> m_levels;
  bool m_phong = false;
  Phong m_ph;
  float m_chroma[2] = {0, 0};
  DirectionInterpolator m_light_interp, m_view_interp;
  ModelStats m_stats;
};

// w_k = clamp(1 - lambda + k, 0, 1) (paper eq. 7).
inline double level_weight(double lod, int k) {
  const double w = 1.0 - lod + double(k);
  return w < 0 ? 0 : (w > 1 ? 1 : w);
}

// Top-level mean vector (d = nL * nV) of one channel under the Phong model.
Eigen::VectorXf phong_mean(const BtfDesc& d, const Phong& p, float chroma[2], int channel);

// Rounds a block to its storage precision (E to half, D per component scaled to |x| <= 1 then
// half), so the in-memory model is exactly what the file holds.
void quantize(Block& b, bool half);

// precision=q (lpyr.h): E and D of level k, channel c as zq tensors (stored in b.coded; E and D
// become their dequantized values), D's step `step` for every column, E column j's step
// step / ||D_j|| (at most 4).
Status quantize_q(Block& b, int k, int c, double step);
// A mean vector of level k, channel c as a zq tensor [d, 1] of step `step` (appended to
// b.coded; b.mean becomes its dequantized value).
Status quantize_mean_q(Block& b, int k, int c, double step);

constexpr uint32_t k_payload_version = 1;
constexpr uint32_t k_flag_phong = 8;  // "levels" tensor flags: bit c = mean of channel c stored

}  // namespace btfc::lpyr
