// Thin products with B in place; see thin_product.h for the contract.
#include "core/thin_product.h"

#include <algorithm>
#include <numeric>
#include <cstdint>
#include <omp.h>
#include <memory>
#include <mutex>
#include <vector>

#include "core/blas_env.h"
#include "core/cpu_dispatch.h"
#include "core/memory.h"

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>

#include "core/avx512_sums.h"
#define BTFC_THIN_AVX512 1
#endif

namespace btfc {

using Eigen::Index;
using MatrixXfR = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
using ConstMapF = Eigen::Map<const Eigen::MatrixXf>;
using ConstStridedF = Eigen::Map<const Eigen::MatrixXf, 0, Eigen::OuterStride<>>;  // B with its leading dimension

namespace {

// Sum of squares of p[0, count) in double, one block (vectorized per clone).
BTFC_CPU_CLONES double block_squares(const float* p, size_t count) {
  double s = 0;
#pragma omp simd reduction(+ : s)
  for (size_t i = 0; i < count; ++i) s += double(p[i]) * double(p[i]);
  return s;
}

#ifdef BTFC_THIN_AVX512
// ---- Z = B^T Y -------------------------------------------------------------------------------
// 8-9 texel columns at a time, their values broadcast against a row of Y (row-major, l values =
// NV zmm registers) into TJ x NV accumulators, with the rows in chunks whose slice of Y stays in
// L2. Each column of B is then read sequentially, TJ streams at a time.
template <int NV, int TJ>
__attribute__((target("avx512f"))) void tn_tile_avx512(const float* B, size_t ldb, const float* Yr, size_t k0, size_t k1, size_t j0,
                                                float* Zr, bool first) {
  constexpr int L = 16 * NV;
  __m512 acc[TJ][NV];
  for (int t = 0; t < TJ; ++t)
    for (int v = 0; v < NV; ++v) acc[t][v] = first ? _mm512_setzero_ps() : _mm512_loadu_ps(Zr + (j0 + t) * L + 16 * v);
  const float* col[TJ];
  for (int t = 0; t < TJ; ++t) col[t] = B + (j0 + t) * ldb;
  for (size_t k = k0; k < k1; ++k) {
    __m512 y[NV];
    for (int v = 0; v < NV; ++v) y[v] = _mm512_loadu_ps(Yr + k * L + 16 * v);
    for (int t = 0; t < TJ; ++t) {
      const __m512 b = _mm512_set1_ps(col[t][k]);
      for (int v = 0; v < NV; ++v) acc[t][v] = _mm512_fmadd_ps(b, y[v], acc[t][v]);
    }
  }
  for (int t = 0; t < TJ; ++t)
    for (int v = 0; v < NV; ++v) _mm512_storeu_ps(Zr + (j0 + t) * L + 16 * v, acc[t][v]);
}

// Sum of squares of p[0, count) in double.
__attribute__((target("avx512f"))) double squares_avx512(const float* p, size_t count) {
  __m512d s0 = _mm512_setzero_pd(), s1 = _mm512_setzero_pd();
  size_t i = 0;
  for (; i + 16 <= count; i += 16) {
    add_squares_pd(_mm512_loadu_ps(p + i), s0, s1);
  }
  double s = reduce_add_pd(_mm512_add_pd(s0, s1));
  for (; i < count; ++i) s += double(p[i]) * double(p[i]);
  return s;
}

// One group of Y's (and Z's) columns: L of them, row-major, zero-padded, multiplied by a tile
// kernel over TJ texel columns at a time (Tile1: one column).
using TnTile = void (*)(const float*, size_t, const float*, size_t, size_t, size_t, float*, bool);
struct TnGroup {
  TnTile tile, tile1;
  size_t tj, L;
};

// Yr: one block of m x L row-major per group, side by side; Zr: as many blocks of n x L. A tile
// of B's columns is multiplied by every group's block in turn, so B is read from memory once
// and again from L1/L2 for the other groups (whose widths may differ: 40 columns as 24 + 16,
// not padded to 48). With `energy`, also ||B||_F^2: each tile's columns are summed again right
// after the tile, from L2 (+4 % of the pass), instead of in a separate pass over memory (which
// took half a pass's time). Squares sums a column segment's squares.
void tn_driver(const float* B, size_t ldb, size_t m, size_t n, const std::vector<TnGroup>& groups, const float* Yr, float* Zr,
               double* energy, double (*squares)(const float*, size_t)) {
  constexpr size_t k_rows = 2048;  // a chunk of Y's rows: 2048 x L floats, in L2
  // Texels per parallel task: whole tiles of every group. With 64, NV 2 (TJ 14) left 8 texels of
  // every task to one-column tiles and ran at 275 GFLOP/s instead of 375 (l = 32,
  // docs/benchmarks.md); one group takes 8 TJ.
  size_t lcm = 1, max_tj = 1;
  for (const TnGroup& g : groups) lcm = std::lcm(lcm, g.tj), max_tj = std::max(max_tj, g.tj);
  const size_t k_texels = lcm * std::max<size_t>(1, 8 * max_tj / lcm);
  std::vector<size_t> y_at(groups.size()), z_at(groups.size());  // each group's block
  for (size_t g = 1; g < groups.size(); ++g) y_at[g] = y_at[g - 1] + m * groups[g - 1].L, z_at[g] = z_at[g - 1] + n * groups[g - 1].L;
  const int64_t tasks = int64_t((n + k_texels - 1) / k_texels);
  std::vector<double> part(energy ? size_t(tasks) : 0, 0.0);
#pragma omp parallel for schedule(dynamic, 1)
  for (int64_t s = 0; s < tasks; ++s) {
    const size_t j0 = size_t(s) * k_texels, j1 = std::min(n, j0 + k_texels);
    double e = 0;
    for (size_t k0 = 0; k0 < m; k0 += k_rows) {
      const size_t k1 = std::min(m, k0 + k_rows);
      for (size_t g = 0; g < groups.size(); ++g) {
        const TnGroup& G = groups[g];
        const bool sum = energy && g == 0;  // the squares of the first group's tile, from L1/L2
        size_t j = j0;
        for (; j + G.tj <= j1; j += G.tj) {
          G.tile(B, ldb, Yr + y_at[g], k0, k1, j, Zr + z_at[g], k0 == 0);
          if (sum)
            for (size_t t = 0; t < G.tj; ++t) e += squares(B + (j + t) * ldb + k0, k1 - k0);
        }
        for (; j < j1; ++j) {
          G.tile1(B, ldb, Yr + y_at[g], k0, k1, j, Zr + z_at[g], k0 == 0);
          if (sum) e += squares(B + j * ldb + k0, k1 - k0);
        }
      }
    }
    if (energy) part[size_t(s)] = e;
  }
  if (energy) {
    *energy = 0;
    for (double v : part) *energy += v;  // fixed order: independent of the thread count
  }
}

template <int NV>
TnGroup tn_group_avx512() {
  constexpr int TJ = std::min(16, (31 - NV) / NV);  // TJ x NV accumulators + NV of Y + 1 broadcast <= 32 registers
  return {tn_tile_avx512<NV, TJ>, tn_tile_avx512<NV, 1>, size_t(TJ), size_t(16 * NV)};
}

// The same tiling for AVX2 (8 lanes, 16 registers: TJ x NV + NV + 1 <= 16), for l <= 32 in one
// group (NV <= 4, TJ >= 2 texels per tile) and up to 96 in groups of 24 and one of the rest
// (8 or 16 columns; tn_driver). Narrow
// products are bound by reading B, which this kernel overlaps with its FMAs, where OpenBLAS
// first packs B and then multiplies. At the UBO2003 size on a 2-core Zen 3 (a plain read of B:
// 0.16-0.18 s), B^T Q took 0.23 / 0.35 / 0.64 / 0.68 / 1.03 / 1.39 s at l = 12 / 24 / 32 / 48 /
// 64 / 96 against OpenBLAS's 0.55 / 0.70 / 0.81 / 1.00 / 1.23 / 1.65 s. One group of 40 or 48
// (TJ 2 or 1) spilled or starved: 4-10 x slower than OpenBLAS (docs/benchmarks.md); 40 as
// 24 + 16 took 0.67 s where two groups of 24 (40 padded to 48) took 0.84 s. The loops
// are unrolled by pragma: without, GCC kept the accumulator array on the stack (a store per FMA).
template <int NV, int TJ>
__attribute__((target("avx2,fma"))) void tn_tile_avx2(const float* B, size_t ldb, const float* Yr, size_t k0, size_t k1, size_t j0,
                                                     float* Zr, bool first) {
  constexpr int L = 8 * NV;
  __m256 acc[TJ][NV];
#pragma GCC unroll 16
  for (int t = 0; t < TJ; ++t)
#pragma GCC unroll 4
    for (int v = 0; v < NV; ++v) acc[t][v] = first ? _mm256_setzero_ps() : _mm256_loadu_ps(Zr + (j0 + t) * L + 8 * v);
  const float* col[TJ];
#pragma GCC unroll 16
  for (int t = 0; t < TJ; ++t) col[t] = B + (j0 + t) * ldb;
  for (size_t k = k0; k < k1; ++k) {
    __m256 y[NV];
#pragma GCC unroll 4
    for (int v = 0; v < NV; ++v) y[v] = _mm256_loadu_ps(Yr + k * L + 8 * v);
#pragma GCC unroll 16
    for (int t = 0; t < TJ; ++t) {
      const __m256 b = _mm256_broadcast_ss(col[t] + k);
#pragma GCC unroll 4
      for (int v = 0; v < NV; ++v) acc[t][v] = _mm256_fmadd_ps(b, y[v], acc[t][v]);
    }
  }
#pragma GCC unroll 16
  for (int t = 0; t < TJ; ++t)
#pragma GCC unroll 4
    for (int v = 0; v < NV; ++v) _mm256_storeu_ps(Zr + (j0 + t) * L + 8 * v, acc[t][v]);
}

template <int NV>
TnGroup tn_group_avx2() {
  constexpr int TJ = (15 - NV) / NV;  // 14, 6, 4, 2 texels per tile
  return {tn_tile_avx2<NV, TJ>, tn_tile_avx2<NV, 1>, size_t(TJ), size_t(8 * NV)};
}

// ---- Y = B X ---------------------------------------------------------------------------------
// The accumulators are 16 TK consecutive rows of CC columns of Y (column-major, so the rows are
// contiguous): per texel j, TK vectors of B's column j (contiguous) times CC broadcast values of
// X's row j (row-major, in L1). A parallel task owns a range of Y's rows, so no reduction and
// no dependence on the thread count; within it, texels go in chunks whose slice of B (rows x
// chunk) is re-read from L1/L2 for each group of CC columns. B's column segments are prefetched
// two row tiles ahead: the tile walks 128 columns at once, too many streams for the hardware
// prefetcher (measured: 215 GFLOP/s without, 280-290 with, OpenBLAS 210-270 on the 2 cores).
constexpr size_t k_nn_rows = 1024;   // rows per parallel task (Y's slice, 1024 x l floats, in L2)
constexpr size_t k_nn_texels = 128;  // texels per chunk (X's slice, 128 x l floats, in L1)
constexpr size_t k_nn_ahead = 2;     // prefetch distance in row tiles

template <int TK, int CC>
__attribute__((target("avx512f"))) void nn_tile_avx512(const float* B, size_t ldb, const float* Xr, size_t lp, size_t k, size_t j0,
                                                size_t j1, size_t c0, float* Y, size_t ldy, bool first, bool prefetch) {
  constexpr size_t R = 16 * TK;
  __m512 acc[TK][CC];
  for (int c = 0; c < CC; ++c)
    for (int t = 0; t < TK; ++t) acc[t][c] = first ? _mm512_setzero_ps() : _mm512_loadu_ps(Y + (c0 + c) * ldy + k + 16 * t);
  for (size_t j = j0; j < j1; ++j) {
    const float* bc = B + j * ldb + k;
    if (prefetch)
      for (int t = 0; t < TK; ++t) _mm_prefetch(reinterpret_cast<const char*>(bc + k_nn_ahead * R + 16 * t), _MM_HINT_T0);
    __m512 b[TK];
    for (int t = 0; t < TK; ++t) b[t] = _mm512_loadu_ps(bc + 16 * t);
    const float* xr = Xr + j * lp + c0;
    for (int c = 0; c < CC; ++c) {
      const __m512 x = _mm512_set1_ps(xr[c]);
      for (int t = 0; t < TK; ++t) acc[t][c] = _mm512_fmadd_ps(b[t], x, acc[t][c]);
    }
  }
  for (int c = 0; c < CC; ++c)
    for (int t = 0; t < TK; ++t) _mm512_storeu_ps(Y + (c0 + c) * ldy + k + 16 * t, acc[t][c]);
}

// The same tile for AVX2 (8 lanes, 16 registers: TK x CC accumulators + TK of B + 1 broadcast
// <= 16): 2 x 6 as BLIS's Haswell sgemm kernel (16 rows x 6 columns), or 3 x 4. Run on Zen 1
// only (thin_product below), where OpenBLAS's B X ran at 33-41 GFLOP/s at l = 36-48 and the
// AVX2 B^T Y at 66-71 (docs/benchmarks.md, 2026-12-07).
template <int TK, int CC>
__attribute__((target("avx2,fma"))) void nn_tile_avx2(const float* B, size_t ldb, const float* Xr, size_t lp, size_t k, size_t j0,
                                                      size_t j1, size_t c0, float* Y, size_t ldy, bool first, bool prefetch) {
  constexpr size_t R = 8 * TK;
  __m256 acc[TK][CC];
#pragma GCC unroll 8
  for (int c = 0; c < CC; ++c)
#pragma GCC unroll 4
    for (int t = 0; t < TK; ++t) acc[t][c] = first ? _mm256_setzero_ps() : _mm256_loadu_ps(Y + (c0 + c) * ldy + k + 8 * t);
  for (size_t j = j0; j < j1; ++j) {
    const float* bc = B + j * ldb + k;
    if (prefetch)
#pragma GCC unroll 4
      for (int t = 0; t < TK; ++t) _mm_prefetch(reinterpret_cast<const char*>(bc + k_nn_ahead * R + 8 * t), _MM_HINT_T0);
    __m256 b[TK];
#pragma GCC unroll 4
    for (int t = 0; t < TK; ++t) b[t] = _mm256_loadu_ps(bc + 8 * t);
    const float* xr = Xr + j * lp + c0;
#pragma GCC unroll 8
    for (int c = 0; c < CC; ++c) {
      const __m256 x = _mm256_broadcast_ss(xr + c);
#pragma GCC unroll 4
      for (int t = 0; t < TK; ++t) acc[t][c] = _mm256_fmadd_ps(b[t], x, acc[t][c]);
    }
  }
#pragma GCC unroll 8
  for (int c = 0; c < CC; ++c)
#pragma GCC unroll 4
    for (int t = 0; t < TK; ++t) _mm256_storeu_ps(Y + (c0 + c) * ldy + k + 8 * t, acc[t][c]);
}

// Rows [0, m / R * R) of Yp (m x lp column-major, leading dimension ldy) through Tile, R rows by
// CC columns; Xr: n x lp row-major, lp a multiple of CC. Each output sums its texels in order.
// Returns m / R * R, the rows written (the caller computes the rest).
using NnTile = void (*)(const float*, size_t, const float*, size_t, size_t, size_t, size_t, size_t, float*, size_t, bool, bool);
template <size_t R, size_t CC, NnTile Tile>
size_t thin_nn(const float* B, size_t ldb, size_t m, size_t n, const float* Xr, size_t lp, float* Yp, size_t ldy) {
  constexpr size_t rows = k_nn_rows / R * R;  // a task holds whole row tiles
  const size_t mfull = m / R * R;
  const int64_t tasks = int64_t((mfull + rows - 1) / rows);
#pragma omp parallel for schedule(dynamic, 1)
  for (int64_t s = 0; s < tasks; ++s) {
    const size_t k0 = size_t(s) * rows, k1 = std::min(mfull, k0 + rows);
    for (size_t j0 = 0; j0 < n; j0 += k_nn_texels) {
      const size_t j1 = std::min(n, j0 + k_nn_texels);
      for (size_t k = k0; k < k1; k += R) {
        const bool prefetch = k + (k_nn_ahead + 1) * R <= m;
        for (size_t c0 = 0; c0 < lp; c0 += CC) Tile(B, ldb, Xr, lp, k, j0, j1, c0, Yp, ldy, j0 == 0, prefetch && c0 == 0);
      }
    }
  }
  return mfull;
}
#endif

// The products where the kernels above do not run, as Eigen products (OpenBLAS when linked) on
// slices in OpenMP threads with one BLAS thread each. OpenBLAS's own pool would spin
// (sched_yield) against the OpenMP threads of the code between the products, e.g. dfmf's
// channel conversion: 30 % of a dfmf encode's samples on a 2-core Zen 3 (docs/benchmarks.md).
// Slices of texels for B^T Y, of rows for B X (a block of B's rows, with B's leading dimension).
// One slice (the caller's thread, BLAS as set) inside a parallel region.
int slices_for(size_t work) {
  if (omp_in_parallel()) return 1;
  const int threads = std::max(1, omp_get_max_threads());
  return int(std::clamp<size_t>(work / 64, 1, size_t(2 * threads)));
}

void eigen_tn(const float* B, size_t ldb, size_t m, size_t n, const ConstRefF& Y, Eigen::Ref<Eigen::MatrixXf> Z) {
  ConstStridedF map(B, Index(m), Index(n), Eigen::OuterStride<>(Index(ldb)));
  const int parts = slices_for(n);
  const SingleThreadedBlas one_blas_thread(parts > 1);
#pragma omp parallel for schedule(dynamic, 1) if (parts > 1)
  for (int p = 0; p < parts; ++p) {
    const Index j0 = Index(n) * p / parts, j1 = Index(n) * (p + 1) / parts;
    Z.middleRows(j0, j1 - j0).noalias() = map.middleCols(j0, j1 - j0).transpose() * Y;
  }
}

void eigen_nn(const float* B, size_t ldb, size_t m, size_t n, const ConstRefF& X, Eigen::Ref<Eigen::MatrixXf> Y) {
  ConstStridedF map(B, Index(m), Index(n), Eigen::OuterStride<>(Index(ldb)));
  const int parts = slices_for(m);
  const SingleThreadedBlas one_blas_thread(parts > 1);
#pragma omp parallel for schedule(dynamic, 1) if (parts > 1)
  for (int p = 0; p < parts; ++p) {
    const Index r0 = Index(m) * p / parts, r1 = Index(m) * (p + 1) / parts;
    Y.middleRows(r0, r1 - r0).noalias() = map.middleRows(r0, r1 - r0) * X;
  }
}

}  // namespace

void transposed_product(const float* B, size_t m, size_t n, const ConstRefF& Y, Eigen::MatrixXf& Z, double* energy, size_t ldb) {
  Z.resize(Index(n), Y.cols());
  transposed_product(B, m, n, Y, Eigen::Ref<Eigen::MatrixXf>(Z), energy, ldb);
}

void thin_product(const float* B, size_t m, size_t n, const ConstRefF& X, Eigen::MatrixXf& Y, size_t ldb) {
  Y.resize(Index(m), X.cols());
  thin_product(B, m, n, X, Eigen::Ref<Eigen::MatrixXf>(Y), ldb);
}

namespace {
#ifdef BTFC_THIN_AVX512
constexpr Index k_tn_avx2_max = 96;  // widest l for the AVX2 kernel (4 groups of 24)

// The staging copy of the last B^T Y's Z, kept for the next (one buffer, process-wide, at most
// 64 MiB): fresh pages cost 1-6 ms per MB on the VMs measured, and at the UBO2003 size faulting
// the 16 MB of a product at l = 40 was a tenth of an in-core SVD's time (docs/benchmarks.md). A
// call that finds the buffer in use (products on several threads) or too small allocates its
// own; the larger one is kept.
class Staging {
 public:
  explicit Staging(size_t count) {
    {
      std::unique_lock<std::mutex> lock(s_mutex, std::try_to_lock);
      if (lock.owns_lock() && s_count >= count) m_p = std::move(s_p), m_count = s_count, s_count = 0;
    }
    if (!m_p) m_p.reset(static_cast<float*>(page_alloc_touched(count * sizeof(float)))), m_count = count;
  }
  ~Staging() {
    if (m_count * sizeof(float) > (size_t(64) << 20)) return;
    std::unique_lock<std::mutex> lock(s_mutex, std::try_to_lock);
    if (lock.owns_lock() && m_count > s_count) s_p = std::move(m_p), s_count = m_count;
  }
  Staging(const Staging&) = delete;
  Staging& operator=(const Staging&) = delete;
  float* data() { return m_p.get(); }

 private:
  std::unique_ptr<float, PageFree> m_p;
  size_t m_count = 0;
  static inline std::mutex s_mutex;
  static inline std::unique_ptr<float, PageFree> s_p;
  static inline size_t s_count = 0;
};

// The AVX2 kernel's groups where it applies (AVX2 + FMA, l <= k_tn_avx2_max); empty otherwise. Up
// to 32 columns in one group; wider, groups of 24 (NV 3, TJ 4: the widest tile that keeps 4
// texels) and one of the remaining 8 or 16 (40 = 24 + 16: a fifth less work than two groups of 24).
std::vector<TnGroup> avx2_groups(Index l) {
  const Index nv = (l + 7) / 8;
  if (!cpu_has_avx2_fma() || l < 1 || l > k_tn_avx2_max) return {};
  const TnGroup k_groups[4] = {tn_group_avx2<1>(), tn_group_avx2<2>(), tn_group_avx2<3>(), tn_group_avx2<4>()};
  std::vector<TnGroup> groups;
  if (nv <= 4) groups.push_back(k_groups[nv - 1]);
  else {
    groups.assign(size_t(nv / 3), k_groups[2]);
    if (nv % 3) groups.push_back(k_groups[nv % 3 - 1]);
  }
  return groups;
}

std::vector<TnGroup> avx512_groups(Index l) {
  const Index nv = (l + 15) / 16;
  if (!cpu_has_avx512f() || nv < 1 || nv > 8) return {};
  const TnGroup k_groups[8] = {tn_group_avx512<1>(), tn_group_avx512<2>(), tn_group_avx512<3>(), tn_group_avx512<4>(),
                               tn_group_avx512<5>(), tn_group_avx512<6>(), tn_group_avx512<7>(), tn_group_avx512<8>()};
  return {k_groups[nv - 1]};
}
#endif
}  // namespace

// Y for the kernels: one block of m x L row-major per group, side by side, zero-padded (tn_driver);
// Y itself for the Eigen products (no groups).
struct StagedY::Impl {
  Index rows = 0, cols = 0;
#ifdef BTFC_THIN_AVX512
  std::vector<TnGroup> groups;
  double (*squares)(const float*, size_t) = nullptr;
  size_t width = 0;  // the groups' widths summed
  std::unique_ptr<float, PageFree> yr;

  void stage(const ConstRefF& Y, std::vector<TnGroup> gs, double (*sq)(const float*, size_t)) {
    groups = std::move(gs), squares = sq, width = 0;
    for (const TnGroup& g : groups) width += g.L;
    yr.reset(static_cast<float*>(page_alloc(size_t(Y.rows()) * width * sizeof(float))));
    size_t at = 0;
    Index c0 = 0;
    for (const TnGroup& g : groups) {
      const Index L = Index(g.L), w = std::max<Index>(0, std::min(L, Y.cols() - c0));
      Eigen::Map<MatrixXfR> Yr(yr.get() + at, Y.rows(), L);
      Yr.leftCols(w) = Y.middleCols(c0, w);
      Yr.rightCols(L - w).setZero();
      at += size_t(Y.rows()) * g.L, c0 += L;
    }
  }
#endif
  Eigen::MatrixXf y;
};

StagedY::StagedY(const ConstRefF& Y) : m_impl(std::make_unique<Impl>()) {
  Impl& s = *m_impl;
  s.rows = Y.rows(), s.cols = Y.cols();
#ifdef BTFC_THIN_AVX512
  if (Y.rows() >= 1) {
    std::vector<TnGroup> g = avx512_groups(Y.cols());
    if (!g.empty()) {
      s.stage(Y, std::move(g), squares_avx512);
      return;
    }
    g = avx2_groups(Y.cols());
    if (!g.empty()) {
      s.stage(Y, std::move(g), block_squares);
      return;
    }
  }
#endif
  s.y = Y;
}
StagedY::~StagedY() = default;
StagedY::StagedY(StagedY&&) noexcept = default;
StagedY& StagedY::operator=(StagedY&&) noexcept = default;
Eigen::Index StagedY::rows() const { return m_impl->rows; }
Eigen::Index StagedY::cols() const { return m_impl->cols; }

void transposed_product(const float* B, size_t m, size_t n, const StagedY& Y, Eigen::Ref<Eigen::MatrixXf> Z, double* energy,
                        size_t ldb) {
  if (ldb == 0) ldb = m;
  const StagedY::Impl& s = Y.impl();
#ifdef BTFC_THIN_AVX512
  if (!s.groups.empty() && n >= 1) {
    // Z through the groups' row-major blocks of n x L, copied out into Z's columns.
    Staging staging(n * s.width);
    float* const zr = staging.data();
    tn_driver(B, ldb, m, n, s.groups, s.yr.get(), zr, energy, s.squares);
    size_t z_at = 0;
    Index c0 = 0;
    for (const TnGroup& g : s.groups) {
      const Index L = Index(g.L), w = std::max<Index>(0, std::min(L, s.cols - c0));
      Eigen::Map<const MatrixXfR> Zr(zr + z_at, Index(n), L);
      Z.middleCols(c0, w) = Zr.leftCols(w);
      z_at += n * g.L, c0 += L;
    }
    return;
  }
  if (!s.groups.empty()) {  // no texels
    if (energy) *energy = 0;
    return;
  }
#endif
  eigen_tn(B, ldb, m, n, s.y, Z);
  if (energy) *energy = squared_norm(B, m, n, ldb);
}

void transposed_product(const float* B, size_t m, size_t n, const ConstRefF& Y, Eigen::Ref<Eigen::MatrixXf> Z, double* energy,
                        size_t ldb) {
  transposed_product(B, m, n, StagedY(Y), Z, energy, ldb);
}

bool transposed_product_avx2(const float* B, size_t m, size_t n, const ConstRefF& Y, Eigen::MatrixXf& Z, double* energy, size_t ldb) {
  Z.resize(Index(n), Y.cols());
#ifdef BTFC_THIN_AVX512
  std::vector<TnGroup> groups = avx2_groups(Y.cols());
  if (groups.empty() || m < 1 || n < 1) return false;
  StagedY staged(Y.topRows(0));  // no rows: nothing staged, then the AVX2 groups (not AVX-512's)
  staged.impl().rows = Y.rows();
  staged.impl().stage(Y, std::move(groups), block_squares);
  transposed_product(B, m, n, staged, Z, energy, ldb);
  return true;
#else
  (void)B, (void)m, (void)n, (void)Y, (void)Z, (void)energy, (void)ldb;
  return false;
#endif
}

namespace {

// Y = B X through the tiles of one instruction set (thin_nn); false where they do not apply (Y
// not written).
enum class NnIsa { avx512, avx2 };
bool nn_tiles(NnIsa isa, const float* B, size_t ldb, size_t m, size_t n, const ConstRefF& X, Eigen::Ref<Eigen::MatrixXf> Y) {
#ifdef BTFC_THIN_AVX512
  const Index l = X.cols();
  const bool wide = isa == NnIsa::avx512;
  if (!(wide ? cpu_has_avx512f() : cpu_has_avx2_fma()) || l < 1 || l > 128 || m < (wide ? 32 : 24) || n < 1) return false;
  // Columns per tile, whichever pads l less: AVX-512 12 or 8 (12: fewer re-reads of B's tile),
  // AVX2 6 (2 x 8 rows) or 4 (3 x 8 rows; 12 accumulators either way, of its 16 registers).
  const Index wider = wide ? 12 : 6, narrower = wide ? 8 : 4;
  const Index cc = (l + wider - 1) / wider * wider <= (l + narrower - 1) / narrower * narrower ? wider : narrower;
  const Index lp = (l + cc - 1) / cc * cc;
  // X row-major and padded in the staging buffer; Y written in place where l needs no padding,
  // else through an m x lp block there. Fresh pages for that block on every call (a pass's
  // parts) faulted for 5 % of a color=dfmf encode's power pass (docs/benchmarks.md).
  const bool direct = lp == l;
  Staging staging(n * size_t(lp) + (direct ? 0 : m * size_t(lp)));
  Eigen::Map<MatrixXfR> Xr(staging.data(), Index(n), lp);
  Xr.leftCols(l) = X;
  Xr.rightCols(lp - l).setZero();
  float* const yp = direct ? Y.data() : staging.data() + n * size_t(lp);
  const size_t ldy = direct ? size_t(Y.outerStride()) : m;
  const auto tiles = !wide      ? (cc == 4 ? thin_nn<24, 4, nn_tile_avx2<3, 4>> : thin_nn<16, 6, nn_tile_avx2<2, 6>>)
                     : cc == 12 ? thin_nn<32, 12, nn_tile_avx512<2, 12>>
                                : thin_nn<32, 8, nn_tile_avx512<2, 8>>;
  const Index mfull = Index(tiles(B, ldb, m, n, Xr.data(), size_t(lp), yp, ldy)), tail = Index(m) - mfull;
  if (!direct) Y.topRows(mfull) = Eigen::Map<const Eigen::MatrixXf>(yp, Index(m), lp).topLeftCorner(mfull, l);
  ConstStridedF map(B, Index(m), Index(n), Eigen::OuterStride<>(Index(ldb)));
  if (tail > 0) Y.bottomRows(tail).noalias() = map.bottomRows(tail) * X;
  return true;
#else
  (void)isa, (void)B, (void)ldb, (void)m, (void)n, (void)X, (void)Y;
  return false;
#endif
}

}  // namespace

// The tiles on AMD's AVX-512 CPUs (Zen 5: 280-290 GFLOP/s against OpenBLAS's 210-270); on Intel's
// OpenBLAS's SkylakeX sgemm, which packs B but still beat them on a 2-core Xeon VM (a whole rank-32
// q 1 SVD of the UBO2003-size matrix 1.78 s against 2.04-2.13 s; docs/benchmarks.md, 2026-12-04).
// Without AVX-512, the AVX2 tiles on Zen 1: on a 2-core EPYC (family 17h model 1) 1.3-1.7 x
// OpenBLAS's ZEN kernels' rate at l = 24-64, never slower at l = 8-128; but on a Zen 3 OpenBLAS's
// kernels beat the same tiling (146-176 against 113-124 GFLOP/s at l = 40-128), and other AVX2
// CPUs were not measured, so they keep OpenBLAS (docs/benchmarks.md, 2026-12-04 and 2026-12-07).
void thin_product(const float* B, size_t m, size_t n, const ConstRefF& X, Eigen::Ref<Eigen::MatrixXf> Y, size_t ldb) {
  if (ldb == 0) ldb = m;
  if (!cpu_is_intel() && nn_tiles(NnIsa::avx512, B, ldb, m, n, X, Y)) return;
  if (cpu_is_zen1() && nn_tiles(NnIsa::avx2, B, ldb, m, n, X, Y)) return;
  eigen_nn(B, ldb, m, n, X, Y);
}

bool thin_product_tiles(const float* B, size_t m, size_t n, const ConstRefF& X, Eigen::MatrixXf& Y, size_t ldb) {
  Y.resize(Index(m), X.cols());
  return nn_tiles(NnIsa::avx512, B, ldb ? ldb : m, m, n, X, Y);
}

bool thin_product_avx2(const float* B, size_t m, size_t n, const ConstRefF& X, Eigen::MatrixXf& Y, size_t ldb) {
  Y.resize(Index(m), X.cols());
  return nn_tiles(NnIsa::avx2, B, ldb ? ldb : m, m, n, X, Y);
}

double squared_norm(const float* B, size_t count) {
  constexpr size_t k_block = size_t(1) << 20;
  const int64_t blocks = int64_t((count + k_block - 1) / k_block);
  std::vector<double> part(size_t(blocks), 0.0);
#pragma omp parallel for schedule(static)
  for (int64_t b = 0; b < blocks; ++b) {
    const size_t i0 = size_t(b) * k_block;
    part[size_t(b)] = block_squares(B + i0, std::min(k_block, count - i0));
  }
  double total = 0;
  for (double v : part) total += v;  // fixed order: independent of the thread count
  return total;
}

double squared_norm(const float* B, size_t m, size_t n, size_t ldb) {
  if (ldb == m) return squared_norm(B, m * n);
  std::vector<double> part(n);
#pragma omp parallel for schedule(static)
  for (int64_t j = 0; j < int64_t(n); ++j) part[size_t(j)] = block_squares(B + size_t(j) * ldb, m);
  double total = 0;
  for (double v : part) total += v;
  return total;
}

}  // namespace btfc
