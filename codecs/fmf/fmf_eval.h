// Random-access evaluation of rgb-mode fmf models on the CPU (issue 24): the throughput path of
// FmfModel::eval_batch when no GPU is used.
//
// An interpolated value is the 3 x 3 blend of measured (light, view) pairs (core/interp.h):
//   f(t, wl, wv) = sum_ab wl_a wv_b  U[pair(l_a, v_b)] . SxV[t]
// which in rgb mode is linear in U, so the pair's rows are blended first (9 axpys over the
// pair's nc x C contiguous floats) and then dotted with the texel's row (nc dots of C).
// Random queries touch 27 scattered rows of U each; U (19683 x 32 floats for UBO2003, 2.5 MB)
// does not fit a core's L2, so a block of queries is first ordered by its dominant direction
// pair (a counting sort, stable): queries near one pair then find its rows in L1, and a run of
// queries with identical weights (a renderer's frame under one light and view) blends once.
// Results go back in the queries' order. The blend has an AVX-512 kernel and an AVX2 kernel
// (fmf_eval.cpp); FmfModel hands it a copy of U and SxV on huge pages (eval_factors()).
// When every value of U is a half float (precision=half, the default, rounds U so) the copy
// holds U as halves too (1.27 MB for UBO2003 at rank 32, inside a 2 MB L2), and an AVX-512 CPU
// blends the queries in their own order from it, unsorted: with U in L2 the sort and the
// scatter back cost what they save (docs/benchmarks.md: 35-36 -> 39-41 M evals/s).
//
// Contract: out[i * nc + c] equals the reference blend of eval_dir (per pair eval() sums, in
// (a, b) order) to float rounding: the blend order differs (rows first, then the dot), and the
// tests assert a relative error <= 1e-5 against the reference.
#pragma once
#include <cstdint>
#include <span>

#include "kernels/btfc_shared.h"

namespace btfc::fmf {

// The factors of an rgb-mode model as stored (row-major, no padding):
//   U [rows][C] with row = c + nc (l + nL v),  SxV [texels][C].
struct EvalFactors {
  const float* U = nullptr;
  const float* SxV = nullptr;
  const uint16_t* Uh = nullptr;  // U as half floats (IEEE binary16 bits), when each value is one
  int C = 0, nc = 3, nL = 0, nV = 0;
};

// Queries as a renderer's index / weight textures give them (btfc_fmf_query: texel and 3 + 3
// (index, barycentric weight) pairs); indices and texels must be in range (not checked here).
// Runs in parallel over blocks of queries (OpenMP).
void eval_weighted(const EvalFactors& f, std::span<const btfc_fmf_query> q, float* out);

// Queries per sorted block: large enough that queries near one pair often meet in the order
// (81 x 81 directions have 6561 pairs), small enough that the block's sorted queries, results
// and converted queries (16384 x 112 B = 1.8 MB per thread, allocated on first use and kept:
// fresh memory faults in slowly on the VMs btfc runs on) stay near a core's L2. 4096-262144 were
// within the machines' noise of each other on Zen 5 (AVX-512); on Zen 3 (AVX2) 16384 was 0-30 %
// faster than 131072 (docs/benchmarks.md). Exposed for the benchmark's block-size sweep.
constexpr size_t k_eval_block = 16384;

// Which blend kernel runs: the best for this CPU (AVX-512 registers, or the AVX2 kernel on CPUs
// without AVX-512), or a named one where the CPU has it, so that tests check every kernel against
// the reference on any machine. Process-wide; for tests and benchmarks. Returns false (and keeps
// the current choice) when this CPU cannot run `path`.
enum class EvalPath { best, avx2, generic };
bool set_eval_path(EvalPath path);
void eval_weighted_block(const EvalFactors& f, const btfc_fmf_query* q, size_t n, float* out);

}  // namespace btfc::fmf
