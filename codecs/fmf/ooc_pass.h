// The pass machinery the streamed SVDs (ooc_svd.cpp: randomized, ooc_exact.cpp: Gram) share:
// reading the owned chunks one ahead on a helper thread, and ending every pass with ONE
// collective sum that also carries the error flag. Internal to codecs/fmf.
//
// Failure contract (the reason this is one piece of code): a process whose chunk read or decode
// fails stops reading but still joins every collective sum of the pass (with flag 1), so no
// process waits forever; after the sum every process sees the flag and returns
// Collective::agree(local), i.e. all of them the lowest failing process's message. Once failed,
// a runner skips the chunks of later passes (it returns at the first failed pass anyway).
#pragma once
#include <Eigen/Dense>
#include <chrono>
#include <functional>
#include <string>
#include <vector>

#include "codecs/fmf/ooc_svd.h"

namespace btfc::fmf {

class PassRunner {
 public:
  // Allocates the chunk buffers (none for a mappable source); an allocation failure becomes the
  // local error, reported at the end of the first pass like a read failure. `progress` (may be
  // null) counts passes x owned chunks under `label`.
  PassRunner(const ChunkSource& src, const std::vector<size_t>& chunks, Collective& coll, Progress* progress, const std::string& label,
             int passes);

  // fn(chunk, B, count) for every owned chunk in order (B: rows x count column-major floats, valid
  // during the call), then pack(sums) copies the local result into sums[0, payload), then the
  // collective sum of payload + 1 doubles (the last one is the error flag). Afterwards sums()
  // holds the global sums. sums() is zeroed to payload + 1 values before the chunks, so fn may
  // add into it directly instead (its data() may move between passes, not within one).
  Status pass(size_t payload, const std::function<void(size_t c, const float* B, size_t count)>& fn,
              const std::function<void(double* sums)>& pack);
  std::vector<double>& sums() { return m_buf; }

  // Frees the chunk buffers and the sum buffer (call after the last pass).
  void release();
  // The end of every streamed SVD: the owned rows of SxV (n x C, zero elsewhere) summed into
  // process 0 (disjoint rows: exact; timed and counted in the stats) and moved into r.SxV there,
  // the progress finished, the stats handed to stats_out (may be null).
  Status finish(SvdResult& r, MatrixXfR& sxv, StreamStats* stats_out);
  // finish() in two steps, for several factorizations from one stream (streaming_svds): gather()
  // once per result, then done() once.
  Status gather(SvdResult& r, MatrixXfR& sxv);
  void done(StreamStats* stats_out);

 private:
  struct Buffers {
    std::vector<uint8_t> raw;
    std::vector<float> block[2];
  };
  Status for_each_chunk(const std::function<void(size_t, const float*, size_t)>& fn);

  const ChunkSource& m_src;
  const std::vector<size_t>& m_chunks;
  Collective& m_coll;
  Progress* m_progress;
  Buffers m_b;
  StreamStats m_st;
  Status m_local;
  std::vector<double> m_buf;
};

// The small eigenproblem every streamed SVD ends with: the top l eigenpairs of the (l x l or
// rows x rows) Gram matrix G, the rank choice (choose_rank: max_rank, target_error, the data's
// rank), S and the energies, in an SvdResult named `method`; E gets the eigenvectors, largest
// first, from which the caller makes U. The rank is r.S.size(). `lapack_from` as top_eigenpairs
// (svd.h): the exact path passes the in-core exact SVD's, so the two solve alike.
SvdResult spectrum_of(const Eigen::MatrixXd& G, Eigen::Index l, double energy, const SvdOptions& opt, const char* method, Eigen::MatrixXd& E,
                      Eigen::Index lapack_from = k_lapack_eigen_from);

}  // namespace btfc::fmf
