// Collective (codecs/fmf/ooc_svd.h) over MPI: sums are MPI_Allreduce / MPI_Reduce of
// doubles / floats (in pieces of at most 2^30 elements: MPI counts are int), and `agree`
// finds the lowest failing rank (MPI_Allreduce MIN) and broadcasts its message, so every rank
// returns the same error and none waits for a rank that gave up.
#pragma once
#include <mpi.h>

#include "core/chunks.h"

namespace btfc {

class MpiCollective final : public Collective {
 public:
  explicit MpiCollective(MPI_Comm comm = MPI_COMM_WORLD);
  int rank() const override { return m_rank; }
  int size() const override { return m_size; }
  Status allreduce_sum(double* data, size_t n) override;
  Status reduce_sum_to_root(float* data, size_t n) override;
  Status agree(const Status& local) override;
  Status broadcast(std::string& s) override;

 private:
  MPI_Comm m_comm;
  int m_rank = 0, m_size = 1;
};

}  // namespace btfc
