// Test helper: P "processes" as threads sharing an Collective (codecs/fmf/ooc_svd.h), for
// the streamed SVD's multi-process tests without MPI.
#pragma once
#include <barrier>
#include <climits>
#include <cstdint>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "core/chunks.h"

namespace btfc::test {

// P "processes" as threads: sums through shared buffers and a barrier, like MPI_Allreduce.
class ThreadGroup {
 public:
  explicit ThreadGroup(int p) : m_p(p), m_bar(p) {}
  class Member final : public Collective {
   public:
    Member(ThreadGroup& g, int r) : m_g(g), m_r(r) {}
    int rank() const override { return m_r; }
    int size() const override { return m_g.m_p; }
    Status allreduce_sum(double* d, size_t n) override {
      m_g.m_bar.arrive_and_wait();
      if (m_r == 0) m_g.m_sum.assign(n, 0.0);
      m_g.m_bar.arrive_and_wait();
      {
        std::lock_guard<std::mutex> lock(m_g.m_mu);
        for (size_t i = 0; i < n; ++i) m_g.m_sum[i] += d[i];
      }
      m_g.m_bar.arrive_and_wait();
      std::copy(m_g.m_sum.begin(), m_g.m_sum.end(), d);
      m_g.m_bar.arrive_and_wait();
      return {};
    }
    Status reduce_sum_to_root(float* d, size_t n) override {
      std::vector<double> x(d, d + n);
      BTFC_RETURN_IF_ERROR(allreduce_sum(x.data(), n));
      if (m_r == 0) std::copy(x.begin(), x.end(), d);
      return {};
    }
    Status agree(const Status& local) override {
      m_g.m_bar.arrive_and_wait();
      if (!local.ok()) {
        std::lock_guard<std::mutex> lock(m_g.m_mu);
        if (m_r < m_g.m_first) m_g.m_first = m_r, m_g.m_err = local;
      }
      m_g.m_bar.arrive_and_wait();
      Status s = m_g.m_first == INT32_MAX ? Status{} : Status(m_g.m_err.code(), "rank " + std::to_string(m_g.m_first) + ": " + m_g.m_err.message());
      m_g.m_bar.arrive_and_wait();
      return s;
    }

   private:
    ThreadGroup& m_g;
    int m_r;
  };

 private:
  int m_p;
  std::barrier<> m_bar;
  std::mutex m_mu;
  std::vector<double> m_sum;
  int m_first = INT32_MAX;
  Status m_err;
};

// Runs fn(member, rank) for ranks 0..P-1, each on its own thread with its own Member, and
// returns when all have finished (a hang would time the test out).
template <class F>
void run_group(int P, F&& fn) {
  ThreadGroup group(P);
  std::vector<std::thread> th;
  for (int r = 0; r < P; ++r)
    th.emplace_back([&, r] {
      ThreadGroup::Member me(group, r);
      fn(me, r);
    });
  for (auto& t : th) t.join();
}

}  // namespace btfc::test
