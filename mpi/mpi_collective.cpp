#include "mpi/mpi_collective.h"

#include <algorithm>
#include <climits>
#include <string>
#include <vector>

namespace btfc {

MpiCollective::MpiCollective(MPI_Comm comm) : m_comm(comm) {
  MPI_Comm_rank(comm, &m_rank);
  MPI_Comm_size(comm, &m_size);
}

static Status mpi_status(int rc, const char* what) {
  if (rc == MPI_SUCCESS) return {};
  char msg[MPI_MAX_ERROR_STRING];
  int len = 0;
  MPI_Error_string(rc, msg, &len);
  return io_error(std::string(what) + " failed: " + std::string(msg, size_t(len)));
}

Status MpiCollective::allreduce_sum(double* data, size_t n) {
  for (size_t i = 0; i < n; i += size_t(1) << 30) {
    const int k = int(std::min(n - i, size_t(1) << 30));
    BTFC_RETURN_IF_ERROR(mpi_status(MPI_Allreduce(MPI_IN_PLACE, data + i, k, MPI_DOUBLE, MPI_SUM, m_comm), "MPI_Allreduce"));
  }
  return {};
}

Status MpiCollective::reduce_sum_to_root(float* data, size_t n) {
  for (size_t i = 0; i < n; i += size_t(1) << 30) {
    const int k = int(std::min(n - i, size_t(1) << 30));
    const int rc = m_rank == 0 ? MPI_Reduce(MPI_IN_PLACE, data + i, k, MPI_FLOAT, MPI_SUM, 0, m_comm)
                               : MPI_Reduce(data + i, nullptr, k, MPI_FLOAT, MPI_SUM, 0, m_comm);
    BTFC_RETURN_IF_ERROR(mpi_status(rc, "MPI_Reduce"));
  }
  return {};
}

Status MpiCollective::agree(const Status& local) {
  int mine = local.ok() ? INT_MAX : m_rank, first = INT_MAX;
  BTFC_RETURN_IF_ERROR(mpi_status(MPI_Allreduce(&mine, &first, 1, MPI_INT, MPI_MIN, m_comm), "MPI_Allreduce"));
  if (first == INT_MAX) return {};
  // The failing rank's code and message, to everyone.
  int code = int(local.code());
  std::string msg = local.message();
  int len = int(msg.size());
  MPI_Bcast(&code, 1, MPI_INT, first, m_comm);
  MPI_Bcast(&len, 1, MPI_INT, first, m_comm);
  msg.resize(size_t(len));
  MPI_Bcast(msg.data(), len, MPI_CHAR, first, m_comm);
  return Status(StatusCode(code), "rank " + std::to_string(first) + ": " + msg);
}

Status MpiCollective::broadcast(std::string& s) {
  unsigned long long n = s.size();
  if (MPI_Bcast(&n, 1, MPI_UNSIGNED_LONG_LONG, 0, m_comm) != MPI_SUCCESS) return io_error("MPI_Bcast failed");
  if (n > (1u << 30)) return invalid_argument("broadcast: string of " + std::to_string(n) + " bytes");
  s.resize(size_t(n));
  if (MPI_Bcast(s.data(), int(n), MPI_CHAR, 0, m_comm) != MPI_SUCCESS) return io_error("MPI_Bcast failed");
  return {};
}

}  // namespace btfc
