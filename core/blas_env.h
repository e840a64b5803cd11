// OpenBLAS 0.3.21 predates Zen 5 and picks its "Haswell" kernels on this CPU; with
// OPENBLAS_CORETYPE=SkylakeX it runs 1.6-1.8x faster (toolchain.md 4b). The variable is read when
// the library loads, before main(), so a program that wants it re-executes itself once with it
// set. Only when the CPU has the AVX-512 subsets those kernels use, and the user has not chosen.
#pragma once

namespace btfc {

// Call first thing in main(). Returns normally when nothing is to be done or exec fails.
void reexec_for_openblas(int argc, char** argv);

// OpenBLAS (the pthreads build Debian ships) knows nothing of OpenMP: a GEMM called from inside
// an OpenMP parallel region still hands work to its own thread pool, whose threads then spin
// (sched_yield) against the OpenMP threads for the same 2 cores. Measured on lpca's per-cluster
// PCA steps (128^2 texels, load ~9): 2.2x slower than with one BLAS thread per caller. Hold one of
// these around parallel regions whose threads call BLAS, or around a run of OpenMP kernels with
// small BLAS calls in between (whose pool would wake and spin against the kernels). Process-wide
// (OpenBLAS has one setting), restored on destruction; a no-op without OpenBLAS, when `when` is
// false (a caller that only sometimes opens a parallel region) and inside a parallel region
// (another thread's holder would race on the one setting).
class SingleThreadedBlas {
 public:
  explicit SingleThreadedBlas(bool when = true);
  ~SingleThreadedBlas();
  SingleThreadedBlas(const SingleThreadedBlas&) = delete;
  SingleThreadedBlas& operator=(const SingleThreadedBlas&) = delete;

 private:
  int saved_ = 0;
};

}  // namespace btfc
