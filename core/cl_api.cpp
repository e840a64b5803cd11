// The dlopen()ed OpenCL function table; see cl_api.h.
#include "core/cl_api.h"

#include <dlfcn.h>

#include <atomic>
#include <cstdlib>
#include <mutex>
#include <string>

namespace btfc::ocl {
namespace {

// The ICD loader's versioned soname (Debian: ocl-icd-libopencl1). Not "libOpenCL.so": that
// unversioned link exists only with the -dev package.
constexpr const char* k_default_library = "libOpenCL.so.1";

std::atomic<bool> g_loaded{false};

Result<const Api*> load() {
  const char* env = std::getenv("BTFC_OPENCL_LIBRARY");
  const std::string lib = env && *env ? env : k_default_library;
  // RTLD_LOCAL: the library's symbols stay out of the global namespace, so they resolve nothing
  // else in the process; RTLD_NOW: a broken library fails here, not in the middle of a kernel.
  void* h = dlopen(lib.c_str(), RTLD_NOW | RTLD_LOCAL);
  if (!h) {
    const char* why = dlerror();
    return Status(StatusCode::device_error,
                  "cannot load the OpenCL library " + lib + " (" + (why ? why : "unknown reason") +
                      "); install an OpenCL ICD loader and driver (apt-get install ocl-icd-libopencl1 pocl-opencl-icd)" +
                      (env && *env ? ", or fix BTFC_OPENCL_LIBRARY" : ""));
  }
  static Api table;
#define BTFC_CL_RESOLVE(f)                                                                                     \
  table.f = reinterpret_cast<decltype(table.f)>(dlsym(h, #f));                                                 \
  if (!table.f) {                                                                                              \
    dlclose(h);                                                                                                \
    return Status(StatusCode::device_error, "the OpenCL library " + lib + " has no function " #f " (not an OpenCL 1.2 library?)"); \
  }
  BTFC_CL_FUNCTIONS(BTFC_CL_RESOLVE)
#undef BTFC_CL_RESOLVE
  // Never dlclose()d: the driver's threads and the per-thread kernels and queues outlive any
  // point where closing would be safe.
  g_loaded = true;
  return static_cast<const Api*>(&table);
}

}  // namespace

Result<const Api*> api() {
  static std::once_flag once;
  static Result<const Api*> result = Status(StatusCode::device_error, "OpenCL library not loaded");
  std::call_once(once, [] { result = load(); });
  return result;
}

bool api_loaded() { return g_loaded; }

}  // namespace btfc::ocl
