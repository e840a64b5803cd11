// Wall-clock timing for the benchmarks (docs/benchmarks.md): seconds on the steady clock, and
// the best of a few repetitions (on a shared machine the best run is the least disturbed one).
#pragma once
#include <algorithm>
#include <chrono>

namespace btfc::bench {

inline double now_s() { return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count(); }

template <class F>
double best_of(int reps, F&& f) {
  double best = 1e30;
  for (int i = 0; i < reps; ++i) {
    const double t = now_s();
    f();
    best = std::min(best, now_s() - t);
  }
  return best;
}

}  // namespace btfc::bench
