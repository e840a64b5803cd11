#include "core/progress.h"

#include <unistd.h>

#include <algorithm>
#include <cstdio>

namespace btfc {

Progress::Progress(bool quiet) : m_enabled(!quiet && isatty(STDERR_FILENO)) {}
Progress::Progress(Callback callback) : m_enabled(bool(callback)), m_callback(std::move(callback)) {}
Progress::~Progress() { finish(); }

void Progress::start(const std::string& label, uint64_t total) {
  std::lock_guard<std::mutex> lock(m_mutex);
  m_label = label;
  m_total = total ? total : 1;
  m_done = 0;
  m_start = m_last = std::chrono::steady_clock::now();
  m_active = true;
}

void Progress::advance(uint64_t n) {
  m_done += n;
  if (m_enabled) draw(false);
}

void Progress::draw(bool force) {
  std::lock_guard<std::mutex> lock(m_mutex);
  if (!m_active) return;
  auto now = std::chrono::steady_clock::now();
  if (!force && now - m_last < std::chrono::milliseconds(100)) return;
  m_last = now;
  if (m_callback) {
    m_callback(m_label, std::min(m_done.load(), m_total), m_total);
    return;
  }
  double frac = double(m_done.load()) / double(m_total);
  if (frac > 1) frac = 1;
  const int width = 30;
  int filled = int(frac * width);
  double secs = std::chrono::duration<double>(now - m_start).count();
  // ETA from the rate so far, once there is a rate (1 % done, or 2 s spent).
  char eta[32] = "  ETA   --";
  if (frac >= 1) std::snprintf(eta, sizeof eta, "  done     ");
  else if (frac > 0.01 || (frac > 0 && secs > 2)) std::snprintf(eta, sizeof eta, "  ETA %5.0fs", secs * (1 - frac) / frac);
  std::fprintf(stderr, "\r%-24s [%.*s%*s] %5.1f%% %6.1fs%s", m_label.c_str(), filled,
               "##############################", width - filled, "", frac * 100, secs, eta);
  std::fflush(stderr);
}

void Progress::finish() {
  if (!m_active) return;
  if (m_enabled) {
    draw(true);
    if (!m_callback) std::fputc('\n', stderr);
  }
  m_active = false;
}

}  // namespace btfc
