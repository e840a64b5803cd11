// Streaming (out-of-core, distributed) SVDs of a BTF matrix B (m rows x n texel columns) that is
// read in column chunks, never held whole. Two algorithms, both ending every pass with one
// collective sum (the pass machinery and its failure handling are shared: ooc_pass.h).
//
// Randomized (streaming_svd): Halko, Martinsson, Tropp 2011, Alg. 4.4 (randomized range finder
// with power iterations), arranged so that every pass reads B exactly once:
//   pass 0        Y = B Omega, ||B||_F^2                      (Omega: n x l Gaussian, l = C + p)
//   pass 1..q     Y = B (B^T Q)  with Q = orth(Y) before each pass  (per chunk: Z_c = B_c^T Q,
//                 Y += B_c Z_c while the chunk is in memory)
//   pass q+1      W^T = B^T Q and G = W W^T (l x l)
//   then          G = E Lambda E^T, U = Q E_k, SxV = W^T E_k   (k by choose_rank)
// The in-core path (svd.h) applies B and B^T the same number of times (1 + 2q + 1) but reads B
// 2q + 2 times; here it is q + 2 reads, each doing two GEMMs per chunk. The only difference is
// that Z = B^T Q is not re-orthonormalised between the two products (Y is, in double, after
// every pass); with float data and the ranks fmf uses this changes the error by far less than
// 1 % (tests/ooc_test.cpp checks it against the in-core path).
//
// Exact (streaming_exact_svd, ooc_exact.cpp): the in-core exact path's rows-side Gram method in
// two passes: pass 1 G = sum_c B_c B_c^T (m x m, double) and ||B||_F^2, then G = E Lambda E^T
// with the in-core solver and rank choice, U = E_k; pass 2 SxV = B_c^T U per chunk. Needs
// streaming_exact_bytes(m) besides the chunk buffers: for matrices with a small row count
// (few directions, any number of texels). The in-core path's other side (B^T B when texels < m)
// is not streamed: it would need every pair of chunks at once.
//
// Omega's rows for chunk c come from an RNG seeded by (seed, first texel of c), so the result
// does not depend on how chunks are spread over processes. Every pass ends with one collective
// sum over processes (Collective::allreduce_sum) of the m x l (or l x l, or G's lower triangle)
// matrix plus one error flag: a process that fails to read or decode a chunk still joins the
// sum, the flag makes every process stop, and Collective::agree hands all of them the failing
// process's message. Sums run in double, so the result equals the single-process one up to
// float rounding.
//
// Memory: one raw chunk buffer and two float chunks (a helper thread reads and decodes the next
// chunk while the current one is multiplied), or two mapped chunks for a mappable source, plus
// O((m + n_local) l) for Y, Q and W^T (randomized) or streaming_exact_bytes(m) (exact). The
// caller sizes chunks so this stays under its limit (ooc_fmf.h).
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "codecs/streaming.h"
#include "core/chunks.h"
#include "core/svd.h"
#include "core/status.h"

namespace btfc::fmf {

// Factorizes B from `chunks` (the chunk indices this process owns; together the processes own
// every chunk exactly once). Returns U (m x C) on every process and SxV (n x C, all texels) on
// process 0 (elsewhere SxV is empty). opt.method is ignored (always randomized); l is clamped
// to min(m, n).
Result<SvdResult> streaming_svd(const ChunkSource& src, const std::vector<size_t>& chunks, const SvdOptions& opt, Collective& coll,
                                StreamStats* stats = nullptr);

// The same contract, exactly (the top singular triplets up to double round-off, as truncated_svd
// with SvdMethod::exact when m <= n) in 2 passes; opt.method, oversample, power_iters and seed
// are ignored. Holds streaming_exact_bytes(m) besides the chunk buffers; the caller checks that
// this fits (it is not checked here).
Result<SvdResult> streaming_exact_svd(const ChunkSource& src, const std::vector<size_t>& chunks, const SvdOptions& opt, Collective& coll,
                                      StreamStats* stats = nullptr);
// Bytes streaming_exact_svd holds for m rows besides the chunk buffers and SxV: the Gram matrix,
// the eigen-solver's workspace and one double column block.
uint64_t streaming_exact_bytes(uint64_t m);

}  // namespace btfc::fmf
