// fmf codec: parameters, encode and load; see fmf.h for the paper, the colour modes and the
// stored tensors, fmf_model.h for how the files of this folder divide the work.
#include <Eigen/Core>
#include <Imath/half.h>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>

#include "codecs/fmf/fmf_model.h"
#include "codecs/fmf/ooc_dfmf.h"
#include "codecs/fmf/ooc_fmf.h"
#include "core/chunks.h"
#include "core/memory.h"
#include "core/quant.h"
#include "core/svd.h"

namespace btfc {
namespace fmf {

const ParamSpec k_params[] = {
    {"rank", ParamSpec::Type::integer, "32", 1, 4096, {}, "components C kept (upper bound when target_error is set)", true},
    {"chroma_rank", ParamSpec::Type::integer, "0", 0, 4096, {}, "color=dfmf: components of the U and V channels (0 = rank)"},
    {"target_error", ParamSpec::Type::real, "0", 0, 1, {}, "if > 0: smallest rank whose relative L2 error of the data (decoded vs input) is <= this"},
    {"color", ParamSpec::Type::choice, "rgb", 0, 0, {"rgb", "dfmf"}, "rgb: colour in the matrix rows (paper); dfmf: per-channel log-luminance/chroma (Bonn DFMF model 11)"},
    {"svd", ParamSpec::Type::choice, "auto", 0, 0, {"auto", "exact", "randomized"}, "auto: exact when the small side of the matrix is <= 1024, or <= 4096 with rank + oversample >= 1/8 of it, else randomized"},
    {"oversample", ParamSpec::Type::integer, "16", 0, 1024, {}, "randomized SVD: extra sketch columns (of the first Krylov block; from power_iters=2 on the later blocks are rank wide)"},
    {"power_iters", ParamSpec::Type::integer, "4", 0, 32, {},
     "randomized SVD: iterations q (in core: block Krylov, at most q + 1 blocks of 2 passes, stops when converged; "
     "out of core: block Krylov on the rows side, at most q + 2 reads of the data, stops when converged)"},
    {"precision", ParamSpec::Type::choice, "half", 0, 0, {"half", "float", "q"},
     "storage of U and SxV: half / float, or q = per-component quantized integers, zstd-coded (fmf_quant.h)"},
    {"bits", ParamSpec::Type::integer, "8", 2, 20, {}, "precision=q: step = 2^-bits x RMS of the strongest eigen-texture (SxV column; per at least rows / 16 texels), U column k's step / sigma_k (equal error per component)"},
    {"textures", ParamSpec::Type::choice, "plain", 0, 0, {"plain", "dct"}, "precision=q: SxV columns coded as integers (plain) or as 8x8 DCT coefficients of the eigen-texture images (dct)"},
    {"offset", ParamSpec::Type::real, "0", 0, k_dfmf_max_offset, {}, "color=dfmf: luminance offset e of Y' = log(Y + e), U' = U / (Y + e); 0 = from the data (sum Y^2 / sum Y over up to 4096 evenly spaced texels); 1e-5 = Bonn's colour model 11 exactly"},
};

std::span<const ParamSpec> params_table() { return k_params; }

// A spec's offset 0 is "from the data" at encode; a model's spec holds the resolved value, so 0
// there is a file from before the parameter existed: Bonn's 1e-5.
Config config_from(const Params& p) {
  Config c;
  c.dfmf = p.get("color") == "dfmf";
  c.half = p.get("precision") == "half";
  if (p.get("precision") == "q") c.quant.bits = int(p.get_int("bits")), c.quant.dct = p.get("textures") == "dct";
  const double e = p.get_real("offset");
  c.offset = e > 0 ? float(e) : k_drr_eps;
  return c;
}

namespace {

// Rounds U and SxV to their storage precision, so the in-memory model is what the file holds.
// (precision=q is float here: FmfModel's constructor quantizes it, knowing the texture size.)
void quantize(Block& b, bool half) {
  b.scale.resize(b.SxV.cols());
  auto round_half = [](float x) { return float(Imath::half(x)); };
  // Column by column on the threads (element-wise: the same bits on any thread count); on one it
  // was 1 % of a UBO2003-size color=dfmf encode.
#pragma omp parallel for schedule(static)
  for (Index c = 0; c < b.SxV.cols(); ++c) {
    const float mx = b.SxV.col(c).cwiseAbs().maxCoeff();
    const float s = (half && mx > 0 && std::isfinite(mx)) ? mx : 1.0f;
    b.scale(c) = s;
    if (!half) continue;
    if (c < b.U.cols()) b.U.col(c) = b.U.col(c).unaryExpr(round_half);
    b.SxV.col(c) = b.SxV.col(c).unaryExpr([&](float x) { return round_half(x / s) * s; });
  }
  if (half && b.U.cols() > b.SxV.cols()) b.U.rightCols(b.U.cols() - b.SxV.cols()) = b.U.rightCols(b.U.cols() - b.SxV.cols()).unaryExpr(round_half);
}

// A factorized block from an SVD result, quantised; its statistics go to `stats`. Fails when the
// factors do not fit float: SxV holds the singular values, which reach ||B||_F, so data of finite
// floats can overflow them (a constant 12 x 10-texel BTF of 1e37 has sigma_1 = 1.5e40), and the
// model would decode to infinities or NaN without a word.
Result<Block> block_from_svd(const std::string& name, SvdResult r, bool half, int max_rank, double target, ModelStats& stats) {
  if (!r.S.allFinite() || (r.S.size() && r.S.maxCoeff() > double(std::numeric_limits<float>::max())) || !r.U.allFinite() ||
      !r.SxV.allFinite())
    return unsupported("fmf: the factors of block '" + name + "' overflow float (a singular value, which reaches the data's " +
                       "norm sqrt(sum of squares), past 3.4e38): the values are too large for fmf; scale the BTF down");
  Block b{name, std::move(r.U), std::move(r.SxV), r.S.cast<float>(), {}, {}};
  quantize(b, half);
  const int kept = int(b.U.cols());
  stats.add("rank." + name, kept);
  stats.add("rel_error." + name, r.rel_error_estimate());
  stats.note("svd." + name, r.method);
  if (r.iterations > 0) stats.add("krylov_blocks." + name, r.iterations);  // passes: in core 2 each, streamed 1 each + 1
  if (kept < max_rank && target == 0)
    stats.note("clamped." + name, "rank " + std::to_string(max_rank) + " clamped to " + std::to_string(kept) +
                                      " (the data's numerical rank limit is " + std::to_string(r.data_rank_limit) + ")");
  if (!r.target_reached) stats.note("target." + name, "target_error not reached at the maximum rank " + std::to_string(max_rank));
  return b;
}

// The spec a model records: a rank the data cannot have (more components than its rows, texels
// or numerical rank; block_from_svd notes it as "clamped.<block>") is stored as the rank kept,
// so that the spec says what the model is. With target_error the rank is an upper bound and
// stays as asked.
Result<Params> with_used_ranks(const Params& p, const std::vector<Block>& blocks) {
  if (p.get_real("target_error") > 0 || blocks.empty()) return p;
  const bool dfmf = blocks.size() == 3;
  const int rank = int(p.get_int("rank")), chroma = int(p.get_int("chroma_rank"));
  const int ky = int(blocks[0].U.cols()), kc = dfmf ? int(std::max(blocks[1].U.cols(), blocks[2].U.cols())) : 0;
  if (ky >= rank && (!dfmf || kc >= (chroma ? chroma : rank))) return p;
  BTFC_ASSIGN_OR_RETURN(Params q, with_value(p, "rank", std::to_string(ky), k_params));
  if (dfmf) return with_value(q, "chroma_rank", std::to_string(kc), k_params);
  return q;
}

class FmfCodec final : public Codec {
 public:
  const char* name() const override { return "fmf"; }
  const char* summary() const override { return "full matrix factorization (truncated SVD), seed 000 section 4"; }
  uint32_t payload_version() const override { return k_payload_version; }
  std::span<const ParamSpec> params() const override { return k_params; }
  // --max-bytes tries half floats and quantized factors at several bit depths (fmf_quant.h),
  // the rank searched for each: at a byte budget the best rank / precision pair depends on how
  // fast the data's singular values decay and how noisy it is. color=dfmf goes down to 3 bits:
  // its Y' takes steps from its variation, not its mean (fmf_quant.h), so at equal bits it holds
  // more than rgb's and the budget's best often lies one bit lower (the real UBO2003 slice at
  // 150 kB: bits 3 rank 6, 33.1 dB, where bits 4 fits rank 2, 30.1 dB); rgb never chose 3 bits at
  // 150 or 400 kB on the slice or the textile (and searched 1.3-2.1x longer with it). Unless
  // the spec gives a chroma rank, dfmf's q settings from 6 bits down also try 4 chroma
  // components (below).
  std::vector<std::string> budget_variants(const Params& spec) const override {
    if (spec.get("color") != "dfmf") return {"precision=half", "precision=q:bits=8", "precision=q:bits=6", "precision=q:bits=5", "precision=q:bits=4"};
    if (spec.get_int("chroma_rank") != 0)  // the user's chroma rank stays
      return {"precision=half", "precision=q:bits=8", "precision=q:bits=6", "precision=q:bits=5", "precision=q:bits=4", "precision=q:bits=3"};
    // A chroma rank equal to the luminance rank spends most of a budget on U' and V', which
    // need few components (colour varies mostly over the texels, little with the directions):
    // with 4 chroma components the bytes buy a higher Y' rank. At equal budgets (`--max-bytes`,
    // chroma_rank=4 against chroma = rank): the UBO2003 slice at 400 kB 36.76 against 35.65 dB,
    // the textile at 300 kB 53.84 / 53.59, synthetic 64 x 64 at 300 kB 40.99 / 38.61, a noisy
    // synthetic 48 x 48 at 250 kB 36.16 / 33.84 (chroma_rank=8 in between on all four). The
    // full chroma rank stays for half, 8 and 6 bits, where a large budget may need it.
    return {"precision=half",
            "precision=q:bits=8",
            "precision=q:bits=6",
            "precision=q:bits=6:chroma_rank=4",
            "precision=q:bits=5:chroma_rank=4",
            "precision=q:bits=4:chroma_rank=4",
            "precision=q:bits=3:chroma_rank=4"};
  }
  // A quarter of the matrix's small side up to 1024, at least one rank per 64 texels. The probes
  // are cheap here: where the exact SVD serves every rank at one cost (small side <= 4096: the
  // 64 x 64 textile, any BTF of few texels or directions) a search computes it once
  // (ExactSvdReuse); larger matrices take the leading components of a few randomized SVDs of
  // growing rank (RandomizedSvdReuse, core/svd.h). One rank per 64 texels alone was far below what
  // a budget of 1:50 - 1:100 buys (issue 22: at 1:100 on the textile, q8 rank 554 at 62.2 dB where
  // rank 64 gave 51.9; on 128 x 128 texels rank 256, a quarter of what 1:100 buys with 8-bit
  // factors), while ranks near the full side cost most (quantizing and coding the widest factors)
  // and gave less (q6 at rank 4096: 60.3 dB).
  long long budget_knob_limit(const BtfDesc& d) const override {
    const long long small = (long long)std::min(d.abrdf_size(), d.num_texels());
    return std::max(components_backed_by_texels(d), std::min<long long>(small / 4, 1024));
  }
  const StreamingEncoder* streaming() const override { return &fmf_streaming(); }

  Result<std::unique_ptr<Model>> encode(const Btf& btf, const Params& p, Context& ctx) const override {
    const BtfDesc& d = btf.desc();
    const Config cfg = config_from(p);
    if (cfg.dfmf && d.channels != 3) return invalid_argument("fmf: color=dfmf needs 3 channels, the BTF has " + std::to_string(d.channels));
    const bool auto_offset = cfg.dfmf && p.get_real("offset") <= 0;
    const auto t0 = std::chrono::steady_clock::now();
    SvdOptions opt;
    opt.target_rel_error = p.get_real("target_error");
    opt.oversample = int(p.get_int("oversample"));
    opt.power_iters = int(p.get_int("power_iters"));
    opt.seed = ctx.seed;
    opt.progress = ctx.progress;
    const std::string m = p.get("svd");
    opt.method = m == "exact" ? SvdMethod::exact : m == "randomized" ? SvdMethod::randomized : SvdMethod::automatic;
    const int rank = int(p.get_int("rank")), chroma = int(p.get_int("chroma_rank"));
    // The input check: a randomized SVD's first pass sums every value's square in double, which
    // is finite exactly when every value is (truncated_svd's and streaming_svds' contract, svd.h,
    // ooc_svd.h): the randomized paths leave it to that pass and name the value after a failure;
    // one read of the BTF fewer (~0.15 s of a 1.7 s rgb or 2.6 s dfmf UBO2003-size encode). The
    // exact paths check first.
    SvdOptions rgb_opt = opt;
    rgb_opt.max_rank = rank;
    const bool svd_checks = !cfg.dfmf && svd_checks_finite(d.abrdf_size(), d.num_texels(), rgb_opt);
    if (!cfg.dfmf && !svd_checks) BTFC_RETURN_IF_ERROR(btf.check_finite("fmf input"));

    std::vector<Block> blocks;
    ModelStats stats;
    // dfmf with target_error: the target is the data's error, which no channel's SVD knows; the
    // channels are factorized at their maximum ranks and truncated afterwards (dfmf_truncate_to_target).
    const bool dfmf_target = cfg.dfmf && opt.target_rel_error > 0;
    auto factor = [&](const std::string& name, const float* B, size_t rows, int max_rank) -> Status {
      opt.max_rank = max_rank;
      SvdOptions o = opt;
      o.truncation_ok = true;  // a rank-C model is the leading C components of a larger one
      if (dfmf_target) o.target_rel_error = 0;
      BTFC_ASSIGN_OR_RETURN(SvdResult r, truncated_svd(B, rows, d.num_texels(), o));
      BTFC_ASSIGN_OR_RETURN(Block b, block_from_svd(name, std::move(r), cfg.half, max_rank, o.target_rel_error, stats));
      blocks.push_back(std::move(b));
      return {};
    };
    Params rp = p;
    if (!cfg.dfmf) {
      // The Btf buffer is B (rows = (view, light, colour), columns = texels), column-major.
      const Status s = factor("rgb", btf.data(), d.abrdf_size(), rank);
      if (!s.ok() && svd_checks && s.code() == StatusCode::corrupt_data) BTFC_RETURN_IF_ERROR(btf.check_finite("fmf input"));  // names it
      BTFC_RETURN_IF_ERROR(s);
    } else {
      const size_t rows = d.num_images(), n = d.num_texels();
      static const char* names[3] = {"y", "u", "v"};
      const int ranks[3] = {rank, chroma ? chroma : rank, chroma ? chroma : rank};
      SvdOptions oc[3] = {opt, opt, opt};
      bool streamed = true;
      for (int k = 0; k < 3; ++k) {
        oc[k].max_rank = ranks[k];
        if (dfmf_target) oc[k].target_rel_error = 0;
        streamed = streamed && resolved_method(rows, n, oc[k]) == SvdMethod::randomized;
      }
      if (!streamed) BTFC_RETURN_IF_ERROR(btf.check_finite("fmf input"));
      // The automatic offset from a sample of the texels (fmf.h): a non-finite value there makes
      // it the fallback, and the first pass then fails on it.
      double e = p.get_real("offset");
      if (auto_offset) e = dfmf_auto_offset(btf);
      BTFC_ASSIGN_OR_RETURN(rp, dfmf_with_offset(p, e));
      const float offset = config_from(rp).offset;
      stats.add("dfmf_offset", offset);
      size_t clamped = 0;
      float* const scratch = streamed && ctx.consumable == &btf && !dfmf_target ? ctx.consumable->data() : nullptr;
      // In a byte-budget search (a RandomizedSvdReuse scope) the probes take the leading
      // components of a few streams at growing ranks (svd.h), keyed by the data's fingerprint
      // (a read of the BTF, so only there), the offset and the SVD options; not when the
      // stream converts the input in place.
      const bool searched = streamed && !scratch && RandomizedSvdReuse::active();
      const std::vector<int> want{ranks[0], ranks[1], ranks[2]};
      uint64_t key = 0;
      auto randomized_at = [&](int r) {
        SvdOptions t = oc[0];
        t.max_rank = r;
        return resolved_method(rows, n, t) == SvdMethod::randomized;
      };
      if (searched) {
        uint32_t offset_bits;
        std::memcpy(&offset_bits, &offset, 4);
        const SvdOptions& o = oc[0];
        key = data_fingerprint(btf.data(), btf.size());
        for (const uint64_t v :
             {uint64_t(offset_bits), uint64_t(rows), uint64_t(n), uint64_t(o.oversample), uint64_t(o.power_iters), uint64_t(o.scheme),
              uint64_t(o.seed), uint64_t(o.sparse_sketch), uint64_t(o.sketch_sums), uint64_t(o.method)})
          key = (key ^ v) * 0x100000001B3ull, key ^= key >> 31;
        // A stream the randomized path cannot grow (a small side the exact path serves): one
        // channel at a time instead, through truncated_svd, which factorizes such a channel
        // exactly and keeps its Gram eigenpairs for every later probe (ExactSvdReuse), and the
        // others (chroma of a few components) randomized as before. The textile's chroma-4
        // setting: a stream at rank 495 took 17 s, then the luminance's exact Gram 13 s more at
        // rank 952.
        if (RandomizedSvdReuse::grows_past_randomized(key, want, randomized_at)) {
          streamed = false;
          BTFC_RETURN_IF_ERROR(btf.check_finite("fmf input"));
        }
      }
      if (streamed) {
        // Randomized: the three channel matrices in one stream over the Btf's own memory
        // (ooc_dfmf.h), each pass converting a part of the data at a time and running every
        // channel's products on it. No channel matrix exists whole: the in-core copy of one
        // took a third of the input (peak 1.40 x the input at UBO2003 size) and 4 s of page
        // faults, and each channel's passes read it again.
        // When the caller lets the encode consume the input (ctx.consumable), each texel is
        // converted once, in the first pass, in the Btf's own memory, and every pass reads the
        // channels there (a fifth to a quarter of the encode at UBO2003 size, docs/benchmarks.md).
        // Not for target_error, whose search compares decodes against the input.
        const MatrixChunks src(btf.data(), d.abrdf_size(), n, std::max<size_t>(1, (size_t(64) << 20) / d.abrdf_size()));
        auto stream = [&](const std::vector<int>& rk) -> Result<RandomizedSvdReuse::Set> {
          SvdOptions oy = oc[0], oca = oc[1];
          oy.max_rank = rk[0], oca.max_rank = std::max(rk[1], rk[2]);
          Collective one;
          double cl = 0;
          BTFC_ASSIGN_OR_RETURN(std::vector<SvdResult> rs,
                                dfmf_streaming_svds(src, owned_chunks(src, 0, 1), offset, oy, oca, one, nullptr, 0, &cl, scratch));
          return RandomizedSvdReuse::Set{std::move(rs), cl};
        };
        Result<RandomizedSvdReuse::Set> r = searched ? RandomizedSvdReuse::serve_set(key, want, randomized_at, stream) : stream(want);
        if (!r.ok() && r.status().code() == StatusCode::corrupt_data) {
          // A non-finite value (ooc_svd.h): named where the input is intact, else (converted in
          // place in the first pass) its texel.
          if (!scratch) BTFC_RETURN_IF_ERROR(btf.check_finite("fmf input"));
          else if (const size_t i = find_non_finite(btf.data(), btf.size()); i < btf.size())
            return corrupt_data("fmf input: non-finite value at texel (" + std::to_string(i / d.abrdf_size() % size_t(d.width)) + ", " +
                                std::to_string(i / d.abrdf_size() / size_t(d.width)) +
                                ") (a NaN or infinity, or finite values whose luminance + offset pass the float range, 3.4e38)");
        }
        BTFC_ASSIGN_OR_RETURN(RandomizedSvdReuse::Set rs, std::move(r));
        for (int k = 0; k < 3; ++k) {
          BTFC_ASSIGN_OR_RETURN(Block b, block_from_svd(names[k], std::move(rs.r[k]), cfg.half, ranks[k], 0, stats));
          blocks.push_back(std::move(b));
        }
        clamped = size_t(rs.extra);
      } else {
        // Exact (small direction sets): one decorrelated channel matrix at a time, peak memory
        // input + 1/3 input. A PageBuffer (huge pages requested, not zeroed): every value is
        // written below, and zero-filling through 4 KiB page faults was most of the encode.
        PageBuffer<float> ch(rows * n);
        for (int k = 0; k < 3; ++k) {
#pragma omp parallel for reduction(+ : clamped) schedule(static)
          for (size_t t = 0; t < n; ++t) {
            const size_t c = dfmf_channel(btf.abrdf(t), rows, k, offset, ch.data() + t * rows);
            if (k == 0) clamped += c;  // the same values clamp in every channel: count them once
          }
          BTFC_RETURN_IF_ERROR(factor(names[k], ch.data(), rows, ranks[k]));
        }
      }
      stats.add("negative_luminance_clamped", double(clamped));
    }
    BTFC_ASSIGN_OR_RETURN(rp, with_used_ranks(rp, blocks));
    auto model = std::make_unique<FmfModel>(d, rp.canonical(), config_from(rp), std::move(blocks));
    if (dfmf_target) {
      BTFC_ASSIGN_OR_RETURN(model, truncate_to_target(btf, std::move(model), opt.target_rel_error, stats));
    }
    stats.add("encode_seconds", std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    model->mutable_stats() = std::move(stats);
    return std::unique_ptr<Model>(std::move(model));
  }

  // color=dfmf target_error: the smallest luminance rank ry (chroma ranks scaled alike,
  // ceil(ry * chroma / rank)) whose decoded BTF has a relative L2 error <= target against the
  // input, by bisection over ry (the error falls with the rank on the data this was measured on;
  // each probe decodes the whole BTF). The full-rank model when even it misses the target (noted).
  static Result<std::unique_ptr<FmfModel>> truncate_to_target(const Btf& btf, std::unique_ptr<FmfModel> full, double target,
                                                               ModelStats& stats) {
    const std::vector<Block>& fb = full->blocks();
    const int ry_max = int(fb[0].U.cols()), rc_max = int(std::max(fb[1].U.cols(), fb[2].U.cols()));
    double norm2 = 0;
    for (size_t i = 0; i < btf.size(); ++i) norm2 += double(btf.data()[i]) * btf.data()[i];
    auto make = [&](int ry) {
      const int rc = std::max(1, int(std::ceil(double(ry) * rc_max / ry_max)));
      std::vector<Block> bs;
      for (size_t k = 0; k < 3; ++k) {
        const Block& b = fb[k];
        const Index c = std::min<Index>(b.U.cols(), k == 0 ? ry : rc);
        bs.push_back({b.name, b.U.leftCols(c), b.SxV.leftCols(c), b.S.head(c), b.scale.head(c), {}});  // a truncation: not the coded tensors
      }
      return std::make_unique<FmfModel>(full->desc(), full->spec(), full->config(), std::move(bs));
    };
    auto error_of = [&](const FmfModel& m) -> Result<double> {
      Btf dec;
      BTFC_RETURN_IF_ERROR(m.decode_all(dec));
      double e2 = 0;
#pragma omp parallel for reduction(+ : e2) schedule(static)
      for (size_t i = 0; i < btf.size(); ++i) {
        const double df = double(dec.data()[i]) - btf.data()[i];
        e2 += df * df;
      }
      return norm2 > 0 ? std::sqrt(e2 / norm2) : std::sqrt(e2);
    };
    BTFC_ASSIGN_OR_RETURN(double err_hi, error_of(*full));
    if (err_hi > target) {
      stats.note("target.data", "target_error " + std::to_string(target) + " not reached: the maximum ranks give " + std::to_string(err_hi));
      stats.add("data_rel_error", err_hi);
      return full;
    }
    int lo = 0, hi = ry_max;  // invariant: hi meets the target, lo does not (0 = none tried)
    double best = err_hi;
    while (hi - lo > 1) {
      const int mid = lo + (hi - lo) / 2;
      BTFC_ASSIGN_OR_RETURN(double e, error_of(*make(mid)));
      if (e <= target) hi = mid, best = e;
      else lo = mid;
    }
    stats.add("data_rel_error", best);
    std::unique_ptr<FmfModel> m = hi == ry_max ? std::move(full) : make(hi);
    for (auto& [k, v] : stats.numbers)  // the ranks the model keeps, in place of the maximum ones
      for (const Block& b : m->blocks())
        if (k == "rank." + b.name) v = double(b.U.cols());
    return m;
  }

  Result<std::unique_ptr<Model>> load(const ContainerReader& rd) const override {
    if (rd.codec().payload_version > k_payload_version)
      return unsupported(rd.path() + ": fmf payload version " + std::to_string(rd.codec().payload_version) +
                         " is newer than this btfc supports (" + std::to_string(k_payload_version) + ")");
    BTFC_ASSIGN_OR_RETURN(auto spec, parse_spec_string(rd.codec().spec));
    BTFC_ASSIGN_OR_RETURN(Params p, bind_params(spec, k_params));
    const Config cfg = config_from(p);
    const BtfDesc& d = rd.desc();
    if (cfg.dfmf && d.channels != 3) return corrupt_data(rd.path() + ": fmf color=dfmf with " + std::to_string(d.channels) + " channels");
    const uint64_t rows = cfg.dfmf ? d.num_images() : d.abrdf_size(), texels = d.num_texels();
    std::vector<Block> blocks;
    const DType dt = cfg.half ? DType::f16 : DType::f32;
    for (const char* name : cfg.dfmf ? std::vector<const char*>{"y", "u", "v"} : std::vector<const char*>{"rgb"}) {
      const std::string b = name;
      const TensorInfo* ti = rd.find("U." + b);
      if (!ti || ti->shape.size() != 2) return corrupt_data(rd.path() + ": fmf tensor 'U." + b + "' missing or not 2-D");
      const uint64_t C = ti->shape[1];
      if (C == 0 || C > 4096) return corrupt_data(rd.path() + ": fmf tensor 'U." + b + "' has " + std::to_string(C) + " components");
      const DType want = cfg.quant.bits > 0 ? DType::zq : dt;
      BTFC_ASSIGN_OR_RETURN(Tensor U, rd.read_checked("U." + b, want, {rows, C}));
      BTFC_ASSIGN_OR_RETURN(Tensor SxV, rd.read_checked("SxV." + b, want, {texels, C}));
      BTFC_ASSIGN_OR_RETURN(Tensor scale, rd.read_checked("scale." + b, DType::f32, {C}));
      BTFC_ASSIGN_OR_RETURN(Tensor S, rd.read_checked("S." + b, DType::f32, {C}));
      const std::string at = rd.path() + ": chunk TNSR '";
      BTFC_ASSIGN_OR_RETURN(std::vector<float> u, want == DType::zq ? quant::decode(U, at + U.name + "'") : U.to_f32());
      BTFC_ASSIGN_OR_RETURN(std::vector<float> sxv, want == DType::zq ? quant::decode(SxV, at + SxV.name + "'") : SxV.to_f32());
      BTFC_ASSIGN_OR_RETURN(std::vector<float> sc, scale.to_f32());
      BTFC_ASSIGN_OR_RETURN(std::vector<float> s, S.to_f32());
      Block blk;
      blk.name = b;
      blk.U = Eigen::Map<MatrixXfR>(u.data(), Index(rows), Index(C));
      blk.SxV = Eigen::Map<MatrixXfR>(sxv.data(), Index(texels), Index(C));
      blk.scale = Eigen::Map<Eigen::VectorXf>(sc.data(), Index(C));
      blk.S = Eigen::Map<Eigen::VectorXf>(s.data(), Index(C));
      for (Index c = 0; c < Index(C); ++c) {
        if (!std::isfinite(blk.scale(c)) || blk.scale(c) <= 0) return corrupt_data(rd.path() + ": fmf tensor 'scale." + b + "' holds a non-positive or non-finite scale");
      }
      if (!blk.U.allFinite() || !blk.SxV.allFinite()) return corrupt_data(rd.path() + ": fmf block '" + b + "' holds non-finite values");
      blk.SxV = blk.SxV * blk.scale.asDiagonal();
      if (want == DType::zq) blk.coded = {std::move(U), std::move(SxV)};
      blocks.push_back(std::move(blk));
    }
    auto model = std::make_unique<FmfModel>(d, p.canonical(), cfg, std::move(blocks));
    for (const Block& b : model->blocks()) model->mutable_stats().add("rank." + b.name, double(b.U.cols()));
    return std::unique_ptr<Model>(std::move(model));
  }
};

}  // namespace
}  // namespace fmf

using namespace fmf;

const Codec& fmf_codec() {
  static const FmfCodec codec;
  return codec;
}

namespace {

// The model of finished factorizations, one per block of the spec's colour mode, as encode()
// makes it (quantisation, per-block rank / error statistics).
Result<std::unique_ptr<Model>> model_from_svds(const BtfDesc& desc, const Params& p, std::vector<SvdResult> rs, ModelStats stats) {
  const Config cfg = config_from(p);
  const size_t rows = cfg.dfmf ? desc.num_images() : desc.abrdf_size();
  if (rs.size() != (cfg.dfmf ? 3u : 1u)) return invalid_argument("fmf: " + std::to_string(rs.size()) + " factorizations for " + p.canonical());
  if (cfg.dfmf && desc.channels != 3) return invalid_argument("fmf: color=dfmf needs 3 channels, the BTF has " + std::to_string(desc.channels));
  const int rank = int(p.get_int("rank")), chroma = int(p.get_int("chroma_rank"));
  static const char* names[3] = {"y", "u", "v"};
  std::vector<Block> blocks;
  for (size_t k = 0; k < rs.size(); ++k) {
    SvdResult& r = rs[k];
    if (size_t(r.U.rows()) != rows || size_t(r.SxV.rows()) != desc.num_texels() || r.U.cols() != r.SxV.cols())
      return invalid_argument("fmf: factor shapes disagree with the BTF (" + desc.summary() + ")");
    const int max_rank = k == 0 ? rank : (chroma ? chroma : rank);
    BTFC_ASSIGN_OR_RETURN(Block b, block_from_svd(cfg.dfmf ? names[k] : "rgb", std::move(r), cfg.half, max_rank, p.get_real("target_error"), stats));
    blocks.push_back(std::move(b));
  }
  BTFC_ASSIGN_OR_RETURN(Params used, with_used_ranks(p, blocks));
  auto model = std::make_unique<FmfModel>(desc, used.canonical(), cfg, std::move(blocks));
  model->mutable_stats() = std::move(stats);
  return std::unique_ptr<Model>(std::move(model));
}

}  // namespace

Result<std::unique_ptr<Model>> make_fmf_model_from_svd(const BtfDesc& desc, const Params& p, SvdResult r, ModelStats stats) {
  if (config_from(p).dfmf) return unsupported("fmf: make_fmf_model_from_svd builds color=rgb models only (color=dfmf: make_dfmf_model_from_svd)");
  std::vector<SvdResult> rs;
  rs.push_back(std::move(r));
  return model_from_svds(desc, p, std::move(rs), std::move(stats));
}

Result<std::unique_ptr<Model>> make_dfmf_model_from_svd(const BtfDesc& desc, const Params& p, SvdResult y, SvdResult u,
                                                        SvdResult v, ModelStats stats) {
  if (!config_from(p).dfmf) return unsupported("fmf: make_dfmf_model_from_svd builds color=dfmf models only");
  std::vector<SvdResult> rs;
  rs.push_back(std::move(y));
  rs.push_back(std::move(u));
  rs.push_back(std::move(v));
  return model_from_svds(desc, p, std::move(rs), std::move(stats));
}

Result<FmfFactorsView> fmf_factors(const Model& model) {
  const auto* m = dynamic_cast<const FmfModel*>(&model);
  if (!m) return invalid_argument(model.spec() + ": not an fmf model");
  const Config& cfg = m->config();
  FmfFactorsView v;
  v.per_channel = cfg.dfmf;
  v.bonn_color_model = cfg.color_model >= 0 ? cfg.color_model : (cfg.dfmf ? 11 : 0);
  v.half = cfg.half;
  v.drr_eps = cfg.dfmf ? cfg.offset : k_drr_eps;
  for (int i = 0; i < 3; ++i) {
    v.color_mean[i] = cfg.color_mean[i];
    for (int j = 0; j < 3; ++j) v.color_transform[i][j] = cfg.color_transform[i][j];
  }
  for (const Block& b : m->blocks())
    v.blocks.push_back({b.name, b.U.data(), b.SxV.data(), b.S.data(), size_t(b.U.rows()), size_t(b.SxV.rows()), int(b.U.cols())});
  return v;
}

}  // namespace btfc
