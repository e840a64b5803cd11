#include "core/blas_env.h"

#include <omp.h>
#include <unistd.h>

#include <cstdlib>

#if defined(BTFC_HAVE_OPENBLAS)
extern "C" {
int openblas_get_num_threads(void);
void openblas_set_num_threads(int);
}
#endif

namespace btfc {

SingleThreadedBlas::SingleThreadedBlas(bool when) {
#if defined(BTFC_HAVE_OPENBLAS)
  if (!when || omp_in_parallel()) return;  // saved_ stays 0: nothing to restore
  saved_ = openblas_get_num_threads();
  if (saved_ > 1) openblas_set_num_threads(1);
#else
  (void)when;
#endif
}

SingleThreadedBlas::~SingleThreadedBlas() {
#if defined(BTFC_HAVE_OPENBLAS)
  if (saved_ > 1) openblas_set_num_threads(saved_);
#endif
}

void reexec_for_openblas(int argc, char** argv) {
#if defined(BTFC_HAVE_OPENBLAS) && defined(__x86_64__)
  if (std::getenv("OPENBLAS_CORETYPE")) return;  // the user's choice (or our own re-exec)
  __builtin_cpu_init();
  if (!__builtin_cpu_supports("avx512f") || !__builtin_cpu_supports("avx512dq") || !__builtin_cpu_supports("avx512bw") ||
      !__builtin_cpu_supports("avx512vl"))
    return;
  setenv("OPENBLAS_CORETYPE", "SkylakeX", 1);
  execv("/proc/self/exe", argv);  // only returns on failure: then carry on with the default kernels
#endif
  (void)argc;
  (void)argv;
}

}  // namespace btfc
