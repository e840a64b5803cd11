// A progress bar on stderr for long work. Silent when stderr is not a terminal or when quiet.
// Thread-safe to advance from several threads; redraws at most every 100 ms.
#pragma once
#include <atomic>
#include <chrono>
#include <cstdint>
#include <mutex>
#include <string>

namespace btfc {

class Progress {
 public:
  explicit Progress(bool quiet = false);
  ~Progress();
  void start(const std::string& label, uint64_t total);
  void advance(uint64_t n = 1);
  void finish();
  bool enabled() const { return m_enabled; }

 private:
  void draw(bool force);
  bool m_enabled = false;
  std::string m_label;
  uint64_t m_total = 0;
  std::atomic<uint64_t> m_done{0};
  std::mutex m_mutex;
  std::chrono::steady_clock::time_point m_start, m_last;
  bool m_active = false;
};

}  // namespace btfc
