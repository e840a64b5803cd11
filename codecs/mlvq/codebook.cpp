// mlvq hierarchical SSIM vector quantization (paper sections 3, 4.1): the top-down leader passes,
// the luminance / chromaticity split, the bottom-up scale refit and the scale quantization.
// Contracts in mlvq_internal.h.
//
// Why a leader pass per level instead of the paper's per-vector recursion: all candidates of a
// level are known once the level above is done (they are the sub-slices of its new entries), so
// each level is one pass in which the SSIM against every existing entry comes from a single GEMM
// of the candidate batch with the entries' prototypes (SSIM needs only the dot product <x, e> on
// top of per-vector sums). Candidates of one batch that match nothing are then compared in order
// with the entries created inside the batch, so the result equals the sequential algorithm's
// (first-come entries, a vector joins the best entry above the threshold). An entry is
// represented by its prototype (the first vector that created it) during the search; its
// stored form (children + scales) is built by the levels below, and the scales are refitted
// against the final reconstructions afterwards, so quantization errors of lower levels are
// compensated by the scales above them.
#include <Eigen/Core>
#include <Imath/half.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <memory>
#include <omp.h>
#include <unordered_map>

#include "codecs/mlvq/mlvq_cl.h"
#include "codecs/mlvq/mlvq_internal.h"
#include "core/blas_env.h"

namespace btfc::mlvq {

using MatrixXfR = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

float store_value(float v, int value_bits) {
  if (value_bits <= 0) return float(Imath::half(v));
  const float q = std::ldexp(1.f, value_bits);
  return std::round(v * q) / q;
}

ScaleCodes quantize_scales(std::vector<float>& v, int bits) {
  ScaleCodes c;
  c.code.resize(v.size());
  float mn = 0, mx = 0;
  for (float x : v)
    if (x > 0) mn = mn == 0 ? x : std::min(mn, x), mx = std::max(mx, x);
  if (mx > 0) {
    c.hi = float(std::log(double(mx)));
    c.lo = float(std::log(double(mn)));
    // 8-bit LDR scales: a 1e4 dynamic range (3.7 % steps); smaller values are rounded up to the
    // bottom of the range (an error below 1e-4 of the stream's largest scale).
    if (bits <= 8) c.lo = std::max(c.lo, c.hi - float(std::log(1e4)));
    // 10-bit scales (the HDR default): a 1e6 dynamic range (1.4 % steps, an RMS error of 0.4 %,
    // far below what the SSIM thresholds accept); 12 bits: 1e9 (0.5 % steps).
    else if (bits <= 10) c.lo = std::max(c.lo, c.hi - float(std::log(1e6)));
    else if (bits <= 12) c.lo = std::max(c.lo, c.hi - float(std::log(1e9)));
  }
  const double q = double((1u << bits) - 1);
  for (size_t i = 0; i < v.size(); ++i) {
    uint16_t code = 0;
    if (v[i] > 0) {
      const double t = c.hi > c.lo ? (std::log(double(v[i])) - c.lo) / (double(c.hi) - c.lo) : 0.0;
      code = uint16_t(1 + std::lround(std::clamp(t, 0.0, 1.0) * (q - 1)));
    }
    c.code[i] = code;
    v[i] = dequantize_scale(code, c.lo, c.hi, bits);
  }
  return c;
}

float dequantize_scale(uint16_t code, float lo, float hi, int bits) {
  if (code == 0) return 0;
  const double q = double((1u << bits) - 1);
  return float(std::exp(double(lo) + (double(code) - 1) * (double(hi) - double(lo)) / (q - 1)));
}

namespace {

struct Origin {
  uint32_t texel, first;  // the slice: nodes [first, first + slice_len) of the texel's grid
};

constexpr uint32_t k_zero = 0xffffffffu;  // "all-zero luminance" marker during a pass

struct PassOut {
  std::vector<uint32_t> idx;
  std::vector<float> scale;
  std::vector<Origin> created;
};

// A batch's product matrix in memory that only grows (doubling): a product per batch into a
// fresh allocation faulted its pages in every time (9 % of an encode of the textile, perf).
struct Scratch {
  std::unique_ptr<float[]> p;
  size_t cap = 0;
  Eigen::Map<MatrixXfR> view(size_t rows, size_t cols) {
    if (rows * cols > cap) cap = std::max(rows * cols, 2 * cap), p.reset(new float[cap]);
    return {p.get(), Eigen::Index(rows), Eigen::Index(cols)};
  }
};

// Z = X E^T (E: k x d row-major) by row blocks on the OpenMP threads, each block one BLAS call on
// its caller's thread (the pass holds SingleThreadedBlas): OpenBLAS's own pool, woken by each
// batch's product, spun (sched_yield) against the scan's OpenMP threads for a fifth of an
// encode (perf, the textile). Blocks of at least 32 rows, where Eigen hands every block to BLAS
// as it does the whole product.
void product_rows(Eigen::Map<MatrixXfR> Z, const MatrixXfR& X, const float* E, size_t k) {
  const Eigen::Index rows = Z.rows(), d = X.cols();
  const int T = int(std::clamp<Eigen::Index>(rows / 32, 1, omp_get_max_threads()));
  const Eigen::Map<const MatrixXfR> Em(E, Eigen::Index(k), d);
#pragma omp parallel for schedule(static) num_threads(T)
  for (int t = 0; t < T; ++t) {
    const Eigen::Index r0 = rows * t / T, r1 = rows * (t + 1) / T;
    Z.middleRows(r0, r1 - r0).noalias() = X.middleRows(r0, r1 - r0) * Em.transpose();
  }
}

// The scan of a batch's candidates (rows of Xl / Xc) against the K0 entries made before it
// (prototypes El / Ec, K0 x dl and K0 x dc row-major): best[i] = the first entry of the largest
// margin (ssim_margins), best_sim[i] its margin, best_scale[i] its scale.
//
// Why blocks: the dot products come from GEMMs of a block of candidates with a chunk of 1024
// entries, scanned while they are in L2, entries in order (a later entry wins only with a larger
// margin, the scan's rule). The whole batch's product (up to 16 M floats, 64 MB) went to memory
// and back three times (Eigen zeroes a product before the BLAS call adds into it, the GEMM writes
// it, the scan reads it), which on the low levels' short vectors (9-18 values) cost more than the
// arithmetic: memset and its page faults were 16 % of an encode of a noisy BTF (perf). The blocks'
// GEMMs round some dot products differently from the batch's one GEMM (OpenBLAS picks its paths by
// shape), so a choice within float rounding of the threshold can differ from the unblocked
// search's; the blocks' shapes depend on the batch alone, never on the thread count.
template <class ScanOf>
void search_entries(const MatrixXfR& Xl, const MatrixXfR& Xc, const std::vector<float>& El, const std::vector<float>& Ec, size_t K0,
                    const EntryTerms& terms, const std::vector<double>& xm, const ScanOf& scan_candidate, std::vector<int>& best,
                    std::vector<double>& best_sim, std::vector<double>& best_scale) {
  const size_t B = size_t(std::max(Xl.rows(), Xc.rows()));
  const Eigen::Index dl = Xl.cols(), dc = Xc.cols();
  // Blocks of 16-128 candidates, at least 4 per batch (the batch shrinks as the codebook grows).
  const size_t RB = std::clamp<size_t>(B / 4 / 16 * 16, 16, 128);
  constexpr size_t KC = 1024;  // a block's products: at most 128 x 1024 floats (512 kB) per part
#pragma omp parallel
  {
    std::vector<float> gl(dl ? RB * KC : 0), gc(dc ? RB * KC : 0);
    std::vector<double> margin(KC), scale(KC);
#pragma omp for schedule(dynamic, 1)
    for (size_t r0 = 0; r0 < B; r0 += RB) {
      const size_t rows = std::min(RB, B - r0);
      for (size_t i = r0; i < r0 + rows; ++i) best[i] = -1, best_sim[i] = -3, best_scale[i] = 1;
      for (size_t j0 = 0; j0 < K0; j0 += KC) {
        const size_t k = std::min(KC, K0 - j0);
        Eigen::Map<MatrixXfR> Gl(gl.data(), Eigen::Index(rows), dl ? Eigen::Index(k) : 0);
        Eigen::Map<MatrixXfR> Gc(gc.data(), Eigen::Index(rows), dc ? Eigen::Index(k) : 0);
        if (dl)
          Gl.noalias() = Xl.middleRows(Eigen::Index(r0), Eigen::Index(rows)) *
                         Eigen::Map<const MatrixXfR>(El.data() + j0 * size_t(dl), Eigen::Index(k), dl).transpose();
        if (dc)
          Gc.noalias() = Xc.middleRows(Eigen::Index(r0), Eigen::Index(rows)) *
                         Eigen::Map<const MatrixXfR>(Ec.data() + j0 * size_t(dc), Eigen::Index(k), dc).transpose();
        for (size_t i = 0; i < rows; ++i) {
          const size_t c = r0 + i;
          ssim_margins(scan_candidate(&xm[5 * c]), terms, j0, k, dl ? &Gl(Eigen::Index(i), 0) : nullptr,
                       dc ? &Gc(Eigen::Index(i), 0) : nullptr, margin.data(), scale.data());
          for (size_t j = 0; j < k; ++j)
            if (margin[j] > best_sim[c]) best_sim[c] = margin[j], best[c] = int(j0 + j), best_scale[c] = scale[j];
        }
      }
    }
  }
}

// One leader pass of part `part` at `level` over `cand` (see the file comment).
// Similarity of a candidate to an entry is its margin over the thresholds: min(lum SSIM - thr_l,
// chroma SSIM - thr_c) over the parts present; an entry is reused when the best margin is >= 0.
PassOut leader_pass(const Btf& btf, const ResamplePlan& plan, int level, Part part, const std::vector<Origin>& cand, double thr_l,
                    double thr_c, bool cl_search) {
  const size_t len = plan.grid.slice_len(level);
  const int dl = part != k_chroma ? int(len) : 0, dc = part != k_lum ? int(2 * len) : 0;
  const size_t d = size_t(dl + dc);
  PassOut out;
  out.idx.assign(cand.size(), 0);
  out.scale.assign(cand.size(), part == k_chroma ? 1.f : 0.f);
  std::vector<float> El, Ec;           // prototypes, K x dl and K x dc
  std::vector<double> em;              // per entry: se, see (lum), sec, seec (chroma)
  EntryTerms terms;                    // the same entries' terms for the CPU scan (ssim_scan.cpp)
  size_t K = 0;
  MatrixXfR Xl, Xc;
  Scratch hl_buf, hc_buf;              // the batches' Gram matrices (Hl, Hc below)
  std::vector<double> xm;              // per candidate: sx, sxx, L, sxc, sxxc
  std::vector<int> best;
  std::vector<double> best_sim, best_scale;
  const size_t bmax = std::clamp<size_t>((size_t(4) << 20) / std::max<size_t>(d, 1), 64, 4096);
  const SingleThreadedBlas one_blas_thread;  // product_rows
  // A candidate's side of the scan from its sums (xm: sx, sxx, peak, sxc, sxxc).
  auto scan_candidate = [&](const double* m) {
    ScanCandidate x;
    x.n_lum = dl, x.sx = m[0], x.sxx = m[1], x.L = m[2];
    x.n_chroma = dc, x.sxc = m[3], x.sxxc = m[4];
    x.thr_l = thr_l, x.thr_c = thr_c;
    return x;
  };
  size_t b0 = 0;
  while (b0 < cand.size()) {
    size_t B = std::min(bmax, cand.size() - b0);
    if (K > 0) B = std::min(B, std::max<size_t>(64, (size_t(16) << 20) / K));
    Xl.resize(Eigen::Index(B), dl);
    Xc.resize(Eigen::Index(B), dc);
    xm.assign(5 * B, 0.0);
#pragma omp parallel for schedule(static)
    for (size_t i = 0; i < B; ++i) {
      const Origin& o = cand[b0 + i];
      extract(plan, btf.abrdf(o.texel), o.first, len, dl ? Xl.row(Eigen::Index(i)).data() : nullptr,
              dc ? Xc.row(Eigen::Index(i)).data() : nullptr);
      double* m = &xm[5 * i];
      for (int j = 0; j < dl; ++j) {
        const double x = Xl(Eigen::Index(i), j);
        m[0] += x, m[1] += x * x, m[2] = std::max(m[2], x);
      }
      for (int j = 0; j < dc; ++j) {
        const double x = Xc(Eigen::Index(i), j);
        m[3] += x, m[4] += x * x;
      }
    }
    const size_t K0 = K;
    best.assign(B, -1);
    best_sim.assign(B, -3);
    best_scale.assign(B, 1);
    if (K0 > 0 && cl_search) {
      SearchProblem sp{int(B), int(K0), dl, dc, Xl.data(), Xc.data(), El.data(), Ec.data(), xm.data(), em.data(), float(thr_l), float(thr_c)};
      SearchResult sr;
      const Status st = ssim_search_cl(sp, sr);
      if (st.ok()) {
        for (size_t i = 0; i < B; ++i) best[i] = sr.idx[i], best_sim[i] = sr.sim[i], best_scale[i] = sr.scale[i];
      } else {
        cl_search = false;  // the device failed: CPU for the rest of the pass (warned by the runtime)
      }
    }
    if (K0 > 0 && !cl_search) search_entries(Xl, Xc, El, Ec, K0, terms, xm, scan_candidate, best, best_sim, best_scale);
    // In order: zero vectors, matches, matches among this batch's new entries, new entries.
    // The dot products with this batch's new entries (prototypes are batch rows) come from the
    // batch's Gram matrices, one GEMM each: the sequential part is then O(B x new entries)
    // SSIM evaluations instead of that many d-long dot products (on noisy data most vectors of
    // a batch are new, and this loop was the encoder's bottleneck).
    Eigen::Map<MatrixXfR> Hl = hl_buf.view(B, dl ? B : 0), Hc = hc_buf.view(B, dc ? B : 0);
    if (dl) product_rows(Hl, Xl, Xl.data(), B);
    if (dc) product_rows(Hc, Xc, Xc.data(), B);
    std::vector<uint32_t> row_of;  // batch row of each entry created in this batch (index j - K0)
    std::vector<float> hl, hc;     // a candidate's dot products with them, in entry order
    std::vector<double> margin, scale;
    for (size_t i = 0; i < B; ++i) {
      const double* m = &xm[5 * i];
      const size_t ci = b0 + i;
      if (dl && m[2] <= 0) {
        out.idx[ci] = k_zero;
        out.scale[ci] = 0;
        continue;
      }
      double bs = best_sim[i], bsc = best_scale[i];
      int bj = best[i];
      if (bs < 0 && K > K0) {
        const size_t k = K - K0;
        hl.resize(k), hc.resize(k), margin.resize(k), scale.resize(k);
        for (size_t j = 0; j < k; ++j) {
          const Eigen::Index r = Eigen::Index(row_of[j]);
          if (dl) hl[j] = Hl(Eigen::Index(i), r);
          if (dc) hc[j] = Hc(Eigen::Index(i), r);
        }
        ssim_margins(scan_candidate(m), terms, K0, k, hl.data(), hc.data(), margin.data(), scale.data());
        for (size_t j = 0; j < k; ++j)
          if (margin[j] > bs) bs = margin[j], bj = int(K0 + j), bsc = scale[j];
      }
      if (bs >= 0 && bj >= 0) {
        out.idx[ci] = uint32_t(bj);
        out.scale[ci] = part == k_chroma ? 1.f : float(bsc);
        continue;
      }
      // A new entry: its prototype is this vector (scale 1).
      if (dl) El.insert(El.end(), Xl.row(Eigen::Index(i)).data(), Xl.row(Eigen::Index(i)).data() + dl);
      if (dc) Ec.insert(Ec.end(), Xc.row(Eigen::Index(i)).data(), Xc.row(Eigen::Index(i)).data() + dc);
      em.insert(em.end(), {m[0], m[1], m[3], m[4]});
      terms.add(dl, dc, m[0], m[1], m[3], m[4]);
      row_of.push_back(uint32_t(i));
      out.idx[ci] = uint32_t(K++);
      out.scale[ci] = 1;
      out.created.push_back(cand[ci]);
    }
    b0 += B;
  }
  // All-zero candidates point at entry 0 with scale 0; a level with nothing but zeros still
  // gets one (zero) entry so every index stays valid.
  if (K == 0 && !cand.empty()) out.created.push_back(cand[0]);
  for (uint32_t& i : out.idx)
    if (i == k_zero) i = 0;
  return out;
}

std::vector<Origin> children(const std::vector<Origin>& created, const Grid& g, int level) {
  std::vector<Origin> c;
  const size_t n = size_t(g.n(level)), len = g.slice_len(level - 1);
  c.reserve(created.size() * n);
  for (const Origin& o : created)
    for (size_t i = 0; i < n; ++i) c.push_back({o.texel, uint32_t(o.first + i * len)});
  return c;
}

// Least-squares scale of x onto r (non-negative), 0 for a zero r.
double ls_scale(const float* x, const float* r, size_t n) {
  double xr = 0, rr = 0;
  for (size_t i = 0; i < n; ++i) xr += double(x[i]) * r[i], rr += double(r[i]) * r[i];
  return rr > 0 ? std::max(0.0, xr / rr) : 0.0;
}

// Refits the scales of book `b` at `level` (part rgb or lum) against the reconstructions of
// its children, then quantizes them.
void refit_book(const Btf& btf, const ResamplePlan& plan, Hierarchy& h, Book& b, int level, Part part,
                const std::vector<Origin>& org) {
  const Grid& g = h.grid;
  const size_t len = g.slice_len(level - 1), n = b.n;
#pragma omp parallel
  {
    std::vector<float> x(len), r(len);
#pragma omp for schedule(dynamic, 4)
    for (size_t e = 0; e < b.K; ++e)
      for (size_t i = 0; i < n; ++i) {
        extract(plan, btf.abrdf(org[e].texel), org[e].first + i * len, len, x.data(), nullptr);
        decode_slice(h, level - 1, part, b.child[e * n + i], 1.f, r.data(), nullptr);
        b.scale[e * n + i] = float(ls_scale(x.data(), r.data(), len));
      }
  }
  ScaleCodes c = quantize_scales(b.scale, h.scale_bits);
  b.scode = std::move(c.code);
  b.lo = c.lo, b.hi = c.hi;
}

}  // namespace

Result<Hierarchy> encode_hierarchy(const Btf& btf, const EncodeOptions& o, EncodeReport& rep) {
  const auto t0 = std::chrono::steady_clock::now();
  const BtfDesc& d = btf.desc();
  if (d.channels != 3 && d.channels != 1) return unsupported("mlvq: needs 1 or 3 channels, got " + std::to_string(d.channels));
  if (o.scheme < 1 || o.scheme > 4) return invalid_argument("mlvq: scheme must be 1..4");
  Hierarchy h;
  h.grid = o.grid;
  h.scheme = o.scheme;
  h.scale_bits = o.scale_bits;
  h.value_bits = o.value_bits;
  const Grid& g = h.grid;
  const int s = o.scheme;
  const ResamplePlan plan = make_plan(d, g);
  const size_t N = d.num_texels();
  if (N >= (size_t(1) << 32) || g.size() >= (size_t(1) << 32)) return unsupported("mlvq: more than 2^32 texels or grid nodes");

  std::vector<Origin> org_rgb[5], org_lum[5], org_chroma[5];
  std::vector<Origin> cand(N);
  for (size_t t = 0; t < N; ++t) cand[t] = {uint32_t(t), 0};
  // Parent arrays of the current level's candidates: the texel maps, then each book's children.
  std::vector<uint32_t>* pidx = &h.texel_idx;
  std::vector<float>* pscale = &h.texel_scale;
  for (int k = 4; k > s; --k) {
    auto tp = std::chrono::steady_clock::now();
    PassOut po = leader_pass(btf, plan, k, k_rgb, cand, o.thr[k], o.thr_chroma[k], o.cl_search);
    rep.pass_seconds[k_rgb][k] = std::chrono::duration<double>(std::chrono::steady_clock::now() - tp).count();
    *pidx = std::move(po.idx);
    *pscale = std::move(po.scale);
    Book& b = h.rgb[k];
    b.K = uint32_t(po.created.size());
    b.n = uint32_t(g.n(k));
    cand = children(po.created, g, k);
    org_rgb[k] = std::move(po.created);
    pidx = &b.child;
    pscale = &b.scale;
  }
  // The split level: luminance and chromaticity codebooks, merged pairwise by M.
  {
    auto tp = std::chrono::steady_clock::now();
    PassOut pl = leader_pass(btf, plan, s, k_lum, cand, o.thr[s], o.thr_chroma[s], o.cl_search);
    auto tq = std::chrono::steady_clock::now();
    PassOut pc = leader_pass(btf, plan, s, k_chroma, cand, o.thr[s], o.thr_chroma[s], o.cl_search);
    rep.pass_seconds[k_lum][s] = std::chrono::duration<double>(tq - tp).count();
    rep.pass_seconds[k_chroma][s] = std::chrono::duration<double>(std::chrono::steady_clock::now() - tq).count();
    std::unordered_map<uint64_t, uint32_t> pairs;
    pidx->resize(cand.size());
    for (size_t i = 0; i < cand.size(); ++i) {
      const uint64_t key = (uint64_t(pl.idx[i]) << 32) | pc.idx[i];
      auto [it, fresh] = pairs.emplace(key, uint32_t(h.merge_lum.size()));
      if (fresh) h.merge_lum.push_back(pl.idx[i]), h.merge_chroma.push_back(pc.idx[i]);
      (*pidx)[i] = it->second;
    }
    *pscale = std::move(pl.scale);
    h.lum[s].K = uint32_t(pl.created.size());
    h.chroma[s].K = uint32_t(pc.created.size());
    org_lum[s] = std::move(pl.created);
    org_chroma[s] = std::move(pc.created);
  }
  for (int k = s; k >= 1; --k) {
    h.lum[k].n = h.chroma[k].n = uint32_t(g.n(k));
    if (k == 1) break;
    auto tp = std::chrono::steady_clock::now();
    PassOut pl = leader_pass(btf, plan, k - 1, k_lum, children(org_lum[k], g, k), o.thr[k - 1], o.thr_chroma[k - 1], o.cl_search);
    auto tq = std::chrono::steady_clock::now();
    PassOut pc = leader_pass(btf, plan, k - 1, k_chroma, children(org_chroma[k], g, k), o.thr[k - 1], o.thr_chroma[k - 1], o.cl_search);
    rep.pass_seconds[k_lum][k - 1] = std::chrono::duration<double>(tq - tp).count();
    rep.pass_seconds[k_chroma][k - 1] = std::chrono::duration<double>(std::chrono::steady_clock::now() - tq).count();
    h.lum[k].child = std::move(pl.idx);
    h.lum[k].scale = std::move(pl.scale);
    h.chroma[k].child = std::move(pc.idx);
    h.lum[k - 1].K = uint32_t(pl.created.size());
    h.chroma[k - 1].K = uint32_t(pc.created.size());
    org_lum[k - 1] = std::move(pl.created);
    org_chroma[k - 1] = std::move(pc.created);
  }

  const auto t_refit = std::chrono::steady_clock::now();
  // Bottom-up: level-1 values (luminance normalized to a maximum of 1, both rounded to half, as
  // stored), then every scale refitted against the final reconstructions and quantized.
  const size_t nb = size_t(g.nbeta);
  {
    Book& l1 = h.lum[1];
    Book& c1 = h.chroma[1];
    l1.values.assign(size_t(l1.K) * nb, 0.f);
    c1.values.assign(size_t(c1.K) * 2 * nb, 0.f);
    for (size_t e = 0; e < l1.K; ++e) {
      float* v = &l1.values[e * nb];
      extract(plan, btf.abrdf(org_lum[1][e].texel), org_lum[1][e].first, nb, v, nullptr);
      const float mx = *std::max_element(v, v + nb);
      for (size_t j = 0; j < nb; ++j) v[j] = mx > 0 ? store_value(v[j] / mx, h.value_bits) : 0.f;
    }
    for (size_t e = 0; e < c1.K; ++e) {
      float* v = &c1.values[e * 2 * nb];
      extract(plan, btf.abrdf(org_chroma[1][e].texel), org_chroma[1][e].first, nb, nullptr, v);
      for (size_t j = 0; j < 2 * nb; ++j) v[j] = store_value(v[j], h.value_bits);
    }
  }
  for (int k = 2; k <= s; ++k) refit_book(btf, plan, h, h.lum[k], k, k_lum, org_lum[k]);
  for (int k = s + 1; k <= 4; ++k) refit_book(btf, plan, h, h.rgb[k], k, k_rgb, org_rgb[k]);
  const size_t G = g.size();
  std::vector<double> mom(5 * N), peak(N);
#pragma omp parallel
  {
    std::vector<float> x(G), r(G);
#pragma omp for schedule(dynamic, 16)
    for (size_t t = 0; t < N; ++t) {
      extract(plan, btf.abrdf(t), 0, G, x.data(), nullptr);
      decode_slice(h, 4, k_rgb, h.texel_idx[t], 1.f, r.data(), nullptr);
      double* m = &mom[5 * t];
      double L = 0;
      for (size_t i = 0; i < G; ++i)
        m[0] += x[i], m[1] += double(x[i]) * x[i], m[2] += r[i], m[3] += double(r[i]) * r[i], m[4] += double(x[i]) * r[i],
            L = std::max(L, double(x[i]));
      peak[t] = L;
      h.texel_scale[t] = (m[3] > 0 && L > 0) ? float(std::max(0.0, m[4] / m[3])) : 0.f;
    }
  }
  {
    ScaleCodes c = quantize_scales(h.texel_scale, h.scale_bits);
    h.texel_scode = std::move(c.code);
    h.texel_lo = c.lo, h.texel_hi = c.hi;
  }
  // Estimated quality: per-texel luminance SSIM of the resampled grid against its
  // reconstruction with the quantized scale (dynamic range: the texel's peak, as in the search).
  double ssim_sum = 0;
#pragma omp parallel for reduction(+ : ssim_sum) schedule(static)
  for (size_t t = 0; t < N; ++t) {
    const double* m = &mom[5 * t];
    if (peak[t] <= 0) {
      ssim_sum += h.texel_scale[t] == 0 ? 1.0 : 0.0;
      continue;
    }
    const double sc = h.texel_scale[t];
    ssim_sum += ssim_from_moments(double(G), m[0], m[1], sc * m[2], sc * sc * m[3], sc * m[4], peak[t], false, nullptr);
  }
  rep.mean_texel_ssim = N ? ssim_sum / double(N) : 1;
  rep.refit_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_refit).count();
  for (int k = 1; k <= 4; ++k) rep.entries[k_rgb][k] = h.rgb[k].K, rep.entries[k_lum][k] = h.lum[k].K, rep.entries[k_chroma][k] = h.chroma[k].K;
  rep.merge_entries = h.merge_size();

  // Resampling alone: measured -> grid -> measured on up to 64 texels, no quantization.
  {
    const size_t step = std::max<size_t>(1, N / 64);
    const size_t nl = d.num_lights(), nv = d.num_views(), nc = size_t(d.channels);
    std::vector<Stencil> st(nl * nv);
    for (size_t v = 0; v < nv; ++v)
      for (size_t l = 0; l < nl; ++l) st[l + nl * v] = measured_stencil(g, d, l, v);
    double num = 0, den = 0;
    std::vector<float> lum(G), chroma(2 * G);
    for (size_t t = 0; t < N; t += step) {
      extract(plan, btf.abrdf(t), 0, G, lum.data(), chroma.data());
      for (size_t r = 0; r < nl * nv; ++r) {
        float rgb[3] = {0, 0, 0};
        const Stencil& S = st[r];
        for (int c = 0; c < 16; ++c) {
          const int ib = S.i[0][c & 1], ia = S.i[1][(c >> 1) & 1], it = S.i[2][(c >> 2) & 1], ip = S.i[3][c >> 3];
          const float w = S.w[0][c & 1] * S.w[1][(c >> 1) & 1] * S.w[2][(c >> 2) & 1] * S.w[3][c >> 3];
          if (w == 0) continue;
          const size_t node = size_t(ib) + nb * (size_t(ia) + size_t(g.nalpha) * (size_t(it) + size_t(g.ntheta) * size_t(ip)));
          const float lrg[3] = {lum[node], chroma[2 * node], chroma[2 * node + 1]};
          float v[3];
          lrg_to_rgb(lrg, v);
          for (int ch = 0; ch < 3; ++ch) rgb[ch] += w * v[ch];
        }
        const float* ref = btf.abrdf(t) + r * nc;
        for (size_t ch = 0; ch < nc; ++ch) {
          const double e = double(rgb[ch]) - ref[ch];
          num += e * e, den += double(ref[ch]) * ref[ch];
        }
      }
    }
    rep.resample_rel_rmse = den > 0 ? std::sqrt(num / den) : 0;
  }
  rep.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return h;
}

}  // namespace btfc::mlvq
