// lpyr codec: parameters and encoding (pyramid + per-level PCA + Phong mean). The paper, the
// exact operators and the stored tensors are described in lpyr.h.
#include "codecs/lpyr/lpyr.h"

#include <chrono>
#include <cmath>

#include "core/quant.h"
#include "core/svd.h"
#include "codecs/lpyr/lpyr_cl.h"
#include "codecs/lpyr/lpyr_internal.h"

namespace btfc {
namespace {

using namespace lpyr;
using Eigen::Index;

constexpr double k_laplacian_mean_fraction = 1e-2;  // auto: keep a Laplacian mean above this share
constexpr double k_phong_tolerance = 0.1;           // auto: Phong when |mu_Y - phong| / |mu_Y| <= this

const ParamSpec k_params[] = {
    {"levels", ParamSpec::Type::integer, "0", 0, 24, {}, "pyramid levels lmax + 1 (1 = plain PCA); 0 = from the data: the paper's stop at ~2 y texels, and no level whose bases cost more than basis_ratio x its weights"},
    {"y", ParamSpec::Type::integer, "8", 1, 4096, {}, "PCA components of Y per level", true},
    {"c", ParamSpec::Type::integer, "2", 1, 4096, {}, "PCA components of Cb and of Cr per level"},
    {"basis_ratio", ParamSpec::Type::integer, "64", 0, 1 << 20, {}, "levels=0: a level of N_k texels is made only when its bases (directions per component) cost at most basis_ratio x its weights (N_k per component); 0 = the paper's rule alone"},
    {"mean", ParamSpec::Type::choice, "auto", 0, 0, {"auto", "phong", "stored"}, "top-level mean: Phong fit (+ Cb/Cr constants), stored vectors, or auto (Phong unless its relative residual > 0.1)"},
    {"laplacian_mean", ParamSpec::Type::choice, "auto", 0, 0, {"auto", "keep", "drop"}, "means of Laplacian levels: auto keeps one carrying > 1 % of its level's energy"},
    {"precision", ParamSpec::Type::choice, "half", 0, 0, {"half", "float", "q"},
     "storage of eigen-vectors and weights (means and Phong f32); q = per-component quantized integers, zstd-coded, stored means too (lpyr.h)"},
    {"bits", ParamSpec::Type::integer, "8", 2, 20, {}, "precision=q: step of the weights = 2^-bits x RMS of the texels' ABRDF norms / sqrt(their gain in the decoded RGB values); eigen-vector j's step / ||D_j|| (equal error per value)"},
};

std::string level_key(int k, int c, const char* what) { return "level" + std::to_string(k) + "." + k_channel_names[c] + "." + what; }

struct Encoder {
  const Btf& btf;
  const Params& p;
  Context& ctx;
  ModelStats stats;

  // PCA of the d x n matrix m (texel-major buffer, modified). `center` (d) is subtracted first
  // when given and becomes the block's mean; for Laplacian levels `policy` decides whether the
  // measured mean is kept.
  // precision=q: the steps' reference D (lpyr.h) and the RGB gain of each channel.
  double q_ref = 0;
  double gain[3] = {1, 1, 1};
  size_t n0 = 1;

  Result<Block> pca(float* m, size_t d, size_t n, int comps, const std::string& policy, const float* center, int k, int c,
                    bool store_center = false) {
    Eigen::Map<Eigen::MatrixXf> M(m, Index(d), Index(n));
    double total = 0;
    Eigen::VectorXd sum = Eigen::VectorXd::Zero(Index(d));
#pragma omp parallel
    {
      Eigen::VectorXd local = Eigen::VectorXd::Zero(Index(d));
      double e = 0;
#pragma omp for schedule(static) nowait
      for (Index t = 0; t < Index(n); ++t) {
        local += M.col(t).cast<double>();
        e += M.col(t).cast<double>().squaredNorm();
      }
#pragma omp critical
      {
        sum += local;
        total += e;
      }
    }
    Eigen::VectorXf mean;
    if (center) {
      mean = Eigen::Map<const Eigen::VectorXf>(center, Index(d));
    } else {
      const Eigen::VectorXd mu = sum / double(n);
      const double frac = total > 0 ? double(n) * mu.squaredNorm() / total : 0;
      stats.add(level_key(k, c, "mean_fraction"), frac);
      if (policy == "keep" || (policy == "auto" && frac > k_laplacian_mean_fraction)) mean = mu.cast<float>();
    }
    const bool q = q_ref > 0;
    Block b;
    // The mean first (a kept Laplacian mean or a stored top mean): the PCA then absorbs its rounding.
    // It is added to the level's n texels, each covering n0 / n level-0 texels: error per entry
    // x n0 x gain.
    if (q && mean.size() && (center ? store_center : true)) {
      b.mean = std::move(mean);
      BTFC_RETURN_IF_ERROR(quantize_mean_q(b, k, c, q_ref / std::sqrt(double(n0) * gain[c])));
      mean = b.mean;
    }
    if (mean.size()) {
#pragma omp parallel for schedule(static)
      for (Index t = 0; t < Index(n); ++t) M.col(t) -= mean;
    }
    const auto t_svd = std::chrono::steady_clock::now();
    SvdOptions opt;
    opt.max_rank = comps;
    opt.seed = ctx.seed + uint64_t(97 * k + c);
    // The exact path eigen-decomposes a min(d, n)^2 Gram matrix (cubic): above 256 the
    // randomized range finder (near-optimal with 4 power iterations) is much faster.
    if (std::min(d, n) > 256) opt.method = SvdMethod::randomized;
    BTFC_ASSIGN_OR_RETURN(SvdResult r, truncated_svd(m, d, n, opt));
    // The level's error relative to its own energy (the mean, when kept, is exact).
    const double resid = std::max(0.0, r.total_energy - r.kept_energy);
    stats.add(level_key(k, c, "rel_error"), total > 0 ? std::sqrt(resid / total) : 0.0);
    stats.add(level_key(k, c, "residual"), std::sqrt(resid));  // Frobenius norm of the PCA error
    stats.add(level_key(k, c, "components"), double(r.U.cols()));
    stats.add(level_key(k, c, "pca_seconds"), std::chrono::duration<double>(std::chrono::steady_clock::now() - t_svd).count());
    b.E = std::move(r.U), b.D = std::move(r.SxV), b.mean = std::move(mean);
    if (q) {
      BTFC_RETURN_IF_ERROR(quantize_q(b, k, c, q_ref / std::sqrt(double(n0) / double(n) * gain[c])));
    } else {
      quantize(b, p.get("precision") == "half");
    }
    return b;
  }

  Result<std::unique_ptr<Model>> run() {
    const BtfDesc& d = btf.desc();
    const auto t_start = std::chrono::steady_clock::now();
    const int ycomp = int(p.get_int("y")), ccomp = int(p.get_int("c"));
    const int basis_ratio = int(p.get_int("basis_ratio"));
    int lmax = auto_lmax(d.width, d.height, ycomp);
    if (basis_ratio > 0) lmax = std::min(lmax, bytes_lmax(d.width, d.height, d.num_images(), basis_ratio));
    if (p.get_int("levels") > 0) {
      const int want = int(p.get_int("levels")) - 1, cap = max_lmax(d.width, d.height);
      lmax = std::min(want, cap);
      if (want > cap)
        stats.note("levels_clamped", std::to_string(want + 1) + " levels asked, " + std::to_string(cap + 1) +
                                         " possible (level " + std::to_string(cap) + " is 1x1)");
    }
    const std::vector<LevelSize> sizes = level_sizes(d.width, d.height, lmax);
    std::vector<Level> levels(size_t(lmax) + 1);
    for (int k = 0; k <= lmax; ++k) levels[size_t(k)].size = sizes[size_t(k)];
    stats.add("lmax", lmax);
    auto comps_at = [&](int, int c) { return c == k_y ? ycomp : ccomp; };
    n0 = d.num_texels();
    if (p.get("precision") == "q") {
      double e = 0;
#pragma omp parallel for reduction(+ : e) schedule(static)
      for (size_t i = 0; i < d.num_values(); ++i) e += double(btf.data()[i]) * btf.data()[i];
      // Per texel of a channel's ABRDF (lights x views values; quant::step_texels).
      q_ref = std::ldexp(std::sqrt(e / quant::step_texels(double(n0), double(d.num_lights() * d.num_views()))),
                         -int(p.get_int("bits")));
      if (!(q_ref > 0) || !std::isfinite(q_ref)) q_ref = 1;  // all-zero data: any step is exact
      for (int c = 0; c < 3; ++c) {  // squared RGB change per unit change of channel c
        float unit[3] = {0, 0, 0}, rgb[3];
        unit[c] = 1;
        ycbcr_to_rgb(unit, rgb);
        gain[c] = double(rgb[0]) * rgb[0] + double(rgb[1]) * rgb[1] + double(rgb[2]) * rgb[2];
      }
      stats.add("q.reference_step", q_ref);
    }

    const size_t dd = d.num_images(), n0 = d.num_texels();
    const std::string lap_policy = p.get("laplacian_mean"), mean_mode = p.get("mean");
    bool phong = false;
    Phong ph;
    float chroma[2] = {0, 0};
    std::vector<float> f, next;
    // One step per (channel, level): the PCAs dominate the time, the finest level most.
    if (ctx.progress) ctx.progress->start("lpyr pyramid and PCA", uint64_t(3 * (lmax + 1)));
    for (int c = 0; c < 3; ++c) {
      // One channel's pyramid at a time bounds the memory at input + 1.33 x input / 3.
      f.assign(n0 * dd, 0.0f);
#pragma omp parallel for schedule(static)
      for (size_t t = 0; t < n0; ++t) {
        const float* a = btf.abrdf(t);
        float* o = f.data() + t * dd;
        for (size_t r = 0; r < dd; ++r) {
          float ycc[3];
          rgb_to_ycbcr(a + 3 * r, ycc);
          o[r] = ycc[c];
        }
      }
      for (int k = 0; k < lmax; ++k) {
        const int comps = comps_at(k, c);
        const LevelSize s = sizes[size_t(k)];
        next.assign(sizes[size_t(k) + 1].texels() * dd, 0.0f);
        BTFC_RETURN_IF_ERROR(reduce_any(f.data(), s.w, s.h, dd, next.data()));  // lpyr_cl.h: kernel or reference
        BTFC_RETURN_IF_ERROR(subtract_up_any(f.data(), s.w, s.h, dd, next.data()));
        BTFC_ASSIGN_OR_RETURN(Block b, pca(f.data(), dd, s.texels(), comps, lap_policy, nullptr, k, c));
        levels[size_t(k)].mean_stored[c] = b.mean.size() != 0;
        levels[size_t(k)].ch[c] = std::move(b);
        f.swap(next);
        if (ctx.progress) ctx.progress->advance();
      }
      // Top level: mean over texels, then the chosen mean model, then PCA around it.
      const size_t nt = sizes[size_t(lmax)].texels();
      std::vector<double> mu(dd, 0.0);
      for (size_t t = 0; t < nt; ++t)
        for (size_t r = 0; r < dd; ++r) mu[r] += f[t * dd + r];
      double avg = 0;
      for (double& m : mu) m /= double(nt), avg += m / double(dd);
      if (c == k_y) {
        const PhongFit fit = fit_phong(d.lights, d.views, mu.data());
        ph = fit.p;
        stats.add("phong.ka", ph.ka), stats.add("phong.kd", ph.kd), stats.add("phong.ks", ph.ks), stats.add("phong.alpha", ph.alpha);
        stats.add("phong.rms_residual", fit.rms_residual);
        stats.add("phong.rel_residual", fit.rel_residual);
        stats.add("phong.iterations", fit.iterations);
        stats.note("phong.method", fit.method);
        const bool poor = fit.rel_residual > k_phong_tolerance;
        phong = mean_mode == "phong" || (mean_mode == "auto" && !poor);
        if (poor)
          stats.note("phong.warning", "Phong describes the top-level Y mean poorly (relative residual " + std::to_string(fit.rel_residual) +
                                          " > " + std::to_string(k_phong_tolerance) + ")" + (phong ? "; mean=stored would store it exactly" : "; the stored mean is used"));
        stats.note("mean", phong ? "phong" : "stored");
      } else {
        chroma[c - 1] = float(avg);
        double e = 0;
        for (double m : mu) e += (m - avg) * (m - avg);
        stats.add(std::string("mean.") + k_channel_names[c] + ".constant", avg);
        stats.add(std::string("mean.") + k_channel_names[c] + ".rms_residual", std::sqrt(e / double(dd)));
      }
      Eigen::VectorXf center(static_cast<Index>(dd));
      if (phong) {
        center = phong_mean(d, ph, chroma, c);
      } else {
        for (size_t r = 0; r < dd; ++r) center(Index(r)) = float(mu[r]);
      }
      BTFC_ASSIGN_OR_RETURN(Block b, pca(f.data(), dd, nt, comps_at(lmax, c), "", center.data(), lmax, c, !phong));
      levels[size_t(lmax)].mean_stored[c] = !phong;
      levels[size_t(lmax)].ch[c] = std::move(b);
      if (ctx.progress) ctx.progress->advance();
    }
    if (ctx.progress) ctx.progress->finish();
    f = {}, next = {};
    stats.add("encode_seconds", std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count());
    Config cfg{p.get("precision") == "half", p.get("precision") == "q" ? int(p.get_int("bits")) : 0};
    // The spec records the levels used (levels=0 resolved, as lpca's clusters=0; levels beyond
    // the texture clamped).
    BTFC_ASSIGN_OR_RETURN(Params used, with_value(p, "levels", std::to_string(lmax + 1), k_params));
    // Finite input near the largest float overflows the YCbCr sums and the PCA (a BTF of values
    // up to 2.8e38 gave infinities and NaN in 5 M of 5.2 M decoded values): an error, not a model.
    for (const Level& l : levels)
      for (const Block& b : l.ch)
        if (!b.E.allFinite() || !b.D.allFinite() || !b.mean.allFinite() || !b.scale.allFinite())
          return unsupported("lpyr: the pyramid's values overflow float (input values near the largest float, 3.4e38): scale the BTF down");
    auto model = std::make_unique<LpyrModel>(d, used.canonical(), cfg, std::move(levels), phong, ph, chroma);
    ModelStats& ms = model->mutable_stats();
    ms.numbers.insert(ms.numbers.begin(), stats.numbers.begin(), stats.numbers.end());
    ms.notes.insert(ms.notes.begin(), stats.notes.begin(), stats.notes.end());
    return std::unique_ptr<Model>(std::move(model));
  }
};

class LpyrCodec final : public Codec {
 public:
  const char* name() const override { return "lpyr"; }
  const char* summary() const override {
    return "Laplacian-pyramid PCA in YCbCr with a Phong mean and continuous level of detail, seed 001 (Ma et al. 2005)";
  }
  uint32_t payload_version() const override { return k_payload_version; }
  std::span<const ParamSpec> params() const override { return k_params; }
  // --max-bytes searches y for half floats and for quantized payloads at three bit depths.
  std::vector<std::string> budget_variants(const Params&) const override {
    return {"precision=half", "precision=q:bits=8", "precision=q:bits=6", "precision=q:bits=4"};
  }
  long long budget_knob_limit(const BtfDesc& d) const override { return components_backed_by_texels(d); }

  Result<std::unique_ptr<Model>> encode(const Btf& btf, const Params& p, Context& ctx) const override {
    const BtfDesc& d = btf.desc();
    if (d.channels != 3) return invalid_argument("lpyr: needs 3 (RGB) channels, the BTF has " + std::to_string(d.channels));
    BTFC_RETURN_IF_ERROR(btf.check_finite("lpyr input"));
    // Peak memory: one channel's level 0 and level 1 stacks next to the input.
    const size_t need = d.num_texels() * d.num_images() * sizeof(float) * 5 / 4;
    if (need > ctx.max_bytes) return invalid_argument("lpyr: encoding needs " + std::to_string(need >> 20) + " MiB of work memory, above the limit");
    Encoder e{btf, p, ctx, {}};
    return e.run();
  }

  Result<std::unique_ptr<Model>> load(const ContainerReader& rd) const override {
    if (rd.codec().payload_version > k_payload_version)
      return unsupported(rd.path() + ": lpyr payload version " + std::to_string(rd.codec().payload_version) +
                         " is newer than this btfc supports (" + std::to_string(k_payload_version) + ")");
    BTFC_ASSIGN_OR_RETURN(auto spec, parse_spec_string(rd.codec().spec));
    if (spec.codec != "lpyr") return corrupt_data(rd.path() + ": codec spec '" + rd.codec().spec + "' is not lpyr");
    BTFC_ASSIGN_OR_RETURN(Params p, bind_params(spec, k_params));
    return LpyrModel::load(rd, std::move(p));
  }
};

}  // namespace

const Codec& lpyr_codec() {
  static const LpyrCodec codec;
  return codec;
}

}  // namespace btfc
