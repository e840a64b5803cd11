// A progress bar on stderr for long work. Silent when stderr is not a terminal or when quiet.
// Thread-safe to advance from several threads; redraws at most every 100 ms.
// A library caller (the Python module's `progress=`) can receive the same updates instead: a
// callback, called at most every 100 ms and once at the end of each stage, under the bar's lock
// (so never concurrently), from whichever thread advanced it.
#pragma once
#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <mutex>
#include <string>

namespace btfc {

class Progress {
 public:
  using Callback = std::function<void(const std::string& label, uint64_t done, uint64_t total)>;
  explicit Progress(bool quiet = false);
  // Updates go to `callback` (not to stderr).
  explicit Progress(Callback callback);
  ~Progress();
  void start(const std::string& label, uint64_t total);
  void advance(uint64_t n = 1);
  void finish();
  bool enabled() const { return m_enabled; }

 private:
  void draw(bool force);
  bool m_enabled = false;
  Callback m_callback;
  std::string m_label;
  uint64_t m_total = 0;
  std::atomic<uint64_t> m_done{0};
  std::mutex m_mutex;
  std::chrono::steady_clock::time_point m_start, m_last;
  bool m_active = false;
};

}  // namespace btfc
