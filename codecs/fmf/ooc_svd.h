// Streaming (out-of-core, distributed) SVDs of a BTF matrix B (m rows x n texel columns) that is
// read in column chunks, never held whole. Two algorithms, both ending every pass with one
// collective sum (the pass machinery and its failure handling are shared: ooc_pass.h).
//
// Randomized (streaming_svd; streaming_svds runs several from one stream): randomized block
// Krylov (Musco and Musco 2015) on the rows side, arranged so that every pass reads B exactly
// once and does at most two products per chunk:
//   pass 0        Y = B Pi, ||B||_F^2   (Pi on the texels, n x l, l = C + p: the in-core path's
//                 first test matrix, svd.h make_column_sketch, a sparse sign sketch S times a
//                 Gaussian, so the pass costs ~ a read: the chunks' B_c S_c are summed in one
//                 m x s buffer, multiplied by G once at the end, SvdOptions::sketch_sums; without
//                 the buffer each chunk adds its B_c S_c G); Q_1 = orth(Y)
//   pass b        Y = B Z with Z = B^T Q_b (per chunk, while it is in memory); Z is kept: it is
//                 block b of W^T = B^T P. Q_{b+1} = orth(Y) against the kept blocks (svd.h,
//                 orthonormalize_against), P = [Q_1 .. Q_{b+1}] (m x (l + b lk), double). The
//                 later blocks are lk = min(l, C) wide for q >= 2, as in core (svd.h
//                 later_krylov_width; else lk = l): Q_2 = orth(Y E) for the top lk
//                 eigenvectors E of Q_1^T Y = Q_1^T B B^T Q_1 (B B^T on Q_1's top Ritz vectors),
//                 so pass 1 is l wide and the later ones lk
//   last pass     the newest block's B^T Q (one product) completes W^T; G = W W^T
//   then          G = E Lambda E^T, U = P E_k, SxV = W^T E_k   (k by choose_rank)
// At most q + 1 blocks (q + 2 reads, as many as the power iterations this replaced). The
// in-core error-driven stop ends it earlier: after pass b the Gram matrix P^T B B^T P of the
// blocks so far is known without a pass (its newest block column is P^T Y), so is the rank-C
// error of that basis, and once a block gains at most k_krylov_stop of it the basis takes
// Q_{b+1} (free) and the last pass follows. Under a tight memory limit P holds only kept_blocks
// blocks: when full, it restarts from its best l + (kept - 2) lk Ritz vectors P E (and W^T from
// W^T E), then adds the next block (kept 1: the best l - lk, then power iterations of lk). The
// in-core path (svd.cpp) runs the same iteration from the same Pi, so with every block kept both
// build the same basis (the same error to float rounding); tests/ooc_test.cpp checks both against
// each other and against the exact SVD.
//
// Exact (streaming_exact_svd, ooc_exact.cpp): the in-core exact path's rows-side Gram method in
// two passes: pass 1 G = sum_c B_c B_c^T (m x m, double) and ||B||_F^2, then G = E Lambda E^T
// with the in-core solver and rank choice, U = E_k; pass 2 SxV = B_c^T U per chunk. Needs
// streaming_exact_bytes(m) besides the chunk buffers: for matrices with a small row count
// (few directions, any number of texels). The in-core path's other side (B^T B when texels < m)
// is not streamed: it would need every pair of chunks at once.
//
// Pi depends on the seed and n only, so the result does not depend on how chunks are spread
// over processes. Every pass ends with one collective
// sum over processes (Collective::allreduce_sum) of the m x l (or l x l, or G's lower triangle)
// matrix plus one error flag: a process that fails to read or decode a chunk still joins the
// sum, the flag makes every process stop, and Collective::agree hands all of them the failing
// process's message. Sums run in double, so the result equals the single-process one up to
// float rounding.
//
// Memory: one raw chunk buffer and two float chunks (a helper thread reads and decodes the next
// chunk while the current one is multiplied), or two mapped chunks for a mappable source, plus
// O((m + n_local) kept l) for P and W^T and the first pass's m x s sums (randomized) or
// streaming_exact_bytes(m) (exact). The
// caller sizes chunks so this stays under its limit (ooc_fmf.h).
#pragma once
#include <cstdint>
#include <functional>
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
// to min(m, n). kept_blocks > 0 caps the blocks P holds (memory: plan_streamed_fmf); with fewer
// than q + 1, P restarts from its Ritz vectors when full (above), 1 being the power iterations.
Result<SvdResult> streaming_svd(const ChunkSource& src, const std::vector<size_t>& chunks, const SvdOptions& opt, Collective& coll,
                                StreamStats* stats = nullptr, int kept_blocks = 0);

// Several matrices from one stream, e.g. color=dfmf's three channel matrices (ooc_dfmf.h): split
// turns a part of a chunk (the source's rows x count floats, column-major; `offset` texels into
// chunk c) into `channels` matrices of `rows` rows (rows x count each, column t of matrix i at
// out[i] + t x ld). Called on the thread that runs the products, one part at a time, parts in
// order. For a stacked first-pass sketch (below) the part buffer holds each column's matrices one
// after the other (out[i] = buffer + i x rows, ld = channels x rows), the layout of a split in
// place; otherwise each matrix contiguous (out[i] = buffer + i x rows x count, ld = rows).
struct ChunkSplit {
  int channels = 1;
  size_t rows = 0;
  std::function<void(size_t c, size_t offset, const float* B, size_t count, float* const* out, size_t ld)> split;
  // Optional, both or neither: where part (c, offset) of the source lies in writable memory
  // whose values the caller no longer needs (an in-memory BTF's own, which MatrixChunks maps),
  // and the split done there: split_in_place turns each of the part's `count` columns (the
  // source's rows) into its values of matrix 0, then 1, ... (`rows` each), so that matrix i is
  // the part's columns from row i x rows on (leading dimension: the source's rows). The first
  // pass splits each part so, the later passes read the matrices back without splitting again
  // and no part buffer is held: color=dfmf converts the BTF once instead of once per pass. The
  // source's values are lost. Needs channels x rows == the source's rows; the results are bit
  // for bit those of `split` when both give the same values. Where every factorization's first
  // pass sums the same sparse sketch (equal texels, buckets and seed: color=dfmf's three at the
  // default chroma rank), that pass sketches each texel's column once, its matrices stacked
  // (column_sketch_sums with a segment per matrix): the same sums, each matrix's energy apart;
  // so does the first pass of a split into part buffers (above).
  std::function<float*(size_t c, size_t offset)> in_place;
  std::function<void(size_t c, size_t offset, float* B, size_t count)> split_in_place;
  size_t part_values = 0;  // values per matrix in a part; 0: ~8 M (tests take small parts)
  // What a non-finite matrix i means besides a NaN or infinity in the source (the first pass's
  // failure, below), e.g. a conversion that overflows finite values; empty: nothing.
  std::function<std::string(size_t i)> non_finite_cause;
};

// streaming_svd of each of split's matrices (opts[i] for matrix i), all in one stream: every
// pass reads each owned chunk once, splits it in parts of ~8 M values per matrix and runs every
// unfinished factorization's products on each part. Each result is streaming_svd's on that
// matrix (its own error-driven stop; the stream ends with the last). The parts take at most a
// chunk's values in floats besides streaming_svd's memory for each matrix. With split null, the
// source itself is the one matrix (streaming_svd). A matrix holding a NaN or an infinity fails
// with corrupt_data after the first pass, on every process, before any product of a later pass:
// its squared norm, summed in double from every value there, is finite exactly when every value
// is (a source's own checks, e.g. a raw .btfc's, name such a value in that pass before).
Result<std::vector<SvdResult>> streaming_svds(const ChunkSource& src, const std::vector<size_t>& chunks, const ChunkSplit* split,
                                              const std::vector<SvdOptions>& opts, Collective& coll, StreamStats* stats = nullptr,
                                              int kept_blocks = 0);

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
