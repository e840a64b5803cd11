// Sparse sign sketches of B's rows (S^T B) and of its columns (B S): the first pass of the block
// Krylov SVDs (core/svd.cpp, codecs/fmf/ooc_svd.cpp: the column sketch, B S, as both build their
// basis on the rows side; the row sketch is the column sketch's test oracle) at memory speed
// instead of GEMM speed.
//
// The randomized range finder starts from B^T Omega with Omega m x l Gaussian (or B Pi, Pi n x l,
// from the other side): a pass of 2 m n l flops, as costly as every later pass. With the composite test matrix Omega = S G (a sparse
// sign embedding S, m x s, with zeta = 1-2 entries +-1 per row, then a Gaussian G, s x l),
// B^T Omega = (S^T B)^T G: S^T B costs zeta adds per element of B (the pass is then bound by
// reading B, not by the FMA units), and the Gaussian acts on the s x n sketch only (2 s n l
// flops, s ~ 256 << m). Sparse sign matrices as test matrices: Martinsson and Tropp,
// "Randomized numerical linear algebra: foundations and algorithms" (Acta Numerica 2020), the
// chapter on linear dimension reduction maps; the zeta = 1 case is Clarkson and Woodruff's
// CountSketch (STOC 2013). Omega's columns are Gaussian mixtures of s signed bucket sums of B's
// rows rather than of the rows themselves; with s >= 4 l the Krylov iteration reaches the same
// error as from a Gaussian start (measured over seeds in docs/benchmarks.md).
//
// The hash works on groups of 16 rows, stratified: row group q (rows 16 q .. 16 q + 15) goes to
// bucket group g, row 16 q + r to bucket 16 g + r, each row with its own random sign; the row
// groups are taken in blocks of G = s / 16, and within each block a random permutation gives
// each bucket group exactly one of them (per layer: zeta layers, each its own permutations and
// signs). A column then adds into s / 16 vector accumulators that stay in registers, reading
// its rows in 1 KB-local order (one vector load, masked negation and add per 16 values and
// layer): the pass runs at the speed of reading B. Deterministic for a seed; each bucket adds
// its rows block by block (layer by layer within a block), the same on every ISA and thread count.
#pragma once
#include <cstddef>
#include <cstdint>
#include <vector>

namespace btfc {

struct SparseSign {
  size_t m = 0, s = 0;  // rows of B; buckets (a multiple of 16)
  size_t layers = 1;    // nonzeros per row (zeta), each from its own permutations and signs
  // Layer t, block position i = G b + k (k < G): the row group that block b gives bucket group k
  // is G b + pick[t Q + i], Q = ceil(m / 16); the last block possibly partial (k < its size).
  std::vector<uint32_t> pick;
  std::vector<uint16_t> negative;  // layer t, row group q: bit r of negative[t Q + q] = row 16 q + r enters negated
};

// A seeded sketch of m rows into s buckets (s rounded up to a multiple of 16, 16 <= s <= 1024),
// `layers` nonzeros per row.
SparseSign make_sparse_sign(size_t m, size_t s, uint64_t seed, size_t layers);

// W = S^T B: B m x n column-major; W s x n column-major (texel j's s sums at W + j s). With
// `energy`, also *energy = ||B||_F^2, summed in double during the pass.
void sparse_sign_product(const float* B, size_t n, const SparseSign& S, float* W, double* energy = nullptr);
// The same, one value at a time on any CPU: the test oracle of the vector path (W bit for bit;
// the energy to round-off), and the path without AVX2.
void sparse_sign_product_reference(const float* B, size_t n, const SparseSign& S, float* W, double* energy = nullptr);
// The AVX2 loop (what CPUs without AVX-512 run), for tests on any CPU that has AVX2 + FMA; false
// (W untouched) elsewhere.
bool sparse_sign_product_avx2(const float* B, size_t n, const SparseSign& S, float* W, double* energy = nullptr);

// The same sketch from the other side, on B's columns: W = B S, B m x n column-major with leading
// dimension ldb >= m (a block of a taller matrix's rows) holding texels [first, first + n) of
// the S.m that S was made for (make_sparse_sign(S.m, s, ...): texel j's bucket and sign as row
// j's above; n < 2^30), W m x s column-major (so the sums over chunks of texels add up to the
// whole matrix's). From 4096 rows on, in texel order: parallel over chunks of 2048 rows, each
// streaming B's texels in storage order into its rows of the s sums (held in L2 / L3). Below,
// in bucket order: parallel over blocks of 2048 rows and ranges of 16 buckets; bucket by bucket,
// each bucket's texels added (or subtracted) into a sum held in L1 while their pieces of B come
// from memory. A pass at about the speed of reading B with one layer (each layer reads B once
// more). W has the same bits in either order. Each
// bucket sums its texels in texel order (layer by layer within a texel), so the result does not
// depend on the thread count. With `energy`, also *energy = ||B||_F^2 in double. The first block
// of the in-core block Krylov SVD (core/svd.cpp). With `accumulate`, W += B S (W not zeroed
// first): calls on consecutive chunks of texels, in order, leave W with the bits of one call on
// them all (each bucket's running sum goes on in texel order); the streamed SVD's first pass.
// With `segment` > 0, B's rows are matrices of `segment` rows stacked (color=dfmf's channels in a
// texel's column) and `energy` gets ceil(m / segment) values, each matrix's ||.||_F^2; W's bits
// do not depend on it.
void sparse_sign_columns(const float* B, size_t ldb, size_t m, size_t n, const SparseSign& S, float* W, double* energy = nullptr,
                         size_t first = 0, bool accumulate = false, size_t segment = 0);

}  // namespace btfc
