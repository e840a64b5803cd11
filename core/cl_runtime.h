// The OpenCL runtime: device selection, one context, one queue per thread, programs built
// once per process and cached, kernels embedded at build time (kernels/*.cl), with a
// development override that loads them from disk.
//
// Device choice (set once per process, e.g. by the CLI's --device):
//   cpu  - never touch OpenCL; every kernel's plain C++ reference runs.
//   cl   - OpenCL is required; failures are errors (StatusCode::device_error).
//   auto - OpenCL when a device works, else warn once on stderr and run the CPU path.
// BTFC_FORCE_CPU=1 forces `cpu` (the test suite's second pass). BTFC_CL_DEVICE picks a device by
// index ("1") or by a substring of its name ("pthread"); default: the first GPU, else the first
// device of any type (PoCL's CPU device here).
// BTFC_KERNEL_DIR=<dir> loads <dir>/<program>.cl and <dir>/btfc_shared.h instead of the embedded
// copies, so kernels can be edited without rebuilding. A failed build returns an error holding the
// full compiler log.
//
// Thread safety: get() and kernel() may be called from any thread; each thread gets its own
// cl_kernel objects (OpenCL kernels are not thread-safe to set arguments on) and its own queue.
#pragma once
#define CL_TARGET_OPENCL_VERSION 120
#include <CL/cl.h>

#include <string>
#include <vector>

#include "core/status.h"

namespace btfc::ocl {

enum class DeviceChoice { automatic, cpu, cl };
// Process-wide choice (default automatic, or cpu when BTFC_FORCE_CPU=1).
void set_device_choice(DeviceChoice c);
DeviceChoice device_choice();
Result<DeviceChoice> parse_device_choice(const std::string& s);  // "auto" | "cpu" | "cl"

struct DeviceInfo {
  std::string platform, name, type, version;
  int compute_units = 0;
  unsigned long long global_mem = 0, max_alloc = 0;
};
// Every device of every platform, in selection-index order.
Result<std::vector<DeviceInfo>> list_devices();

class Runtime {
 public:
  // The process's runtime, created on first use. Errors when OpenCL is unavailable.
  static Result<Runtime*> get();
  cl_context context() const { return m_context; }
  cl_device_id device() const { return m_device; }
  const DeviceInfo& info() const { return m_info; }
  // This thread's queue.
  Result<cl_command_queue> queue();
  // This thread's kernel `name` from program `program` (kernels/<program>.cl), built on first use.
  Result<cl_kernel> kernel(const std::string& program, const std::string& name);

 private:
  Runtime() = default;
  cl_platform_id m_platform = nullptr;
  cl_device_id m_device = nullptr;
  cl_context m_context = nullptr;
  DeviceInfo m_info;
};

// Should this call use OpenCL? automatic: yes if the runtime works (else warns once, "no");
// cl: yes (errors surface later from get()); cpu: no. `why` receives the fallback reason.
bool use_opencl(std::string* why = nullptr);
// After an OpenCL path failed with `s`: under `auto`, records the reason, warns once and returns
// true (run the CPU path); under `cl`, returns false (the caller reports `s`).
bool fall_back_after(const Status& s);
// The reason OpenCL was not used in this process ("" when it was, or was not asked for).
std::string fallback_reason();

// Source of kernels/<program>.cl with kernels/btfc_shared.h prepended (embedded or from
// BTFC_KERNEL_DIR).
Result<std::string> kernel_source(const std::string& program);

// Where this process's kernels ran, for statistics: "opencl: <device>", "cpu: <reason>".
std::string device_summary();

// "CL_OUT_OF_RESOURCES (-5)"
std::string cl_error_name(cl_int err);

// Sets kernel argument i to v; a failure is a device_error naming `what` and the CL error.
template <class T>
Status set_arg(cl_kernel k, int i, const T& v, const char* what = "clSetKernelArg") {
  const cl_int e = clSetKernelArg(k, cl_uint(i), sizeof(T), &v);
  if (e != CL_SUCCESS) return Status(StatusCode::device_error, std::string(what) + ": " + cl_error_name(e));
  return {};
}

// A device buffer that releases itself.
class Buffer {
 public:
  Buffer() = default;
  ~Buffer() { reset(); }
  Buffer(Buffer&& o) noexcept : m_mem(o.m_mem) { o.m_mem = nullptr; }
  Buffer& operator=(Buffer&& o) noexcept {
    if (this != &o) reset(), m_mem = o.m_mem, o.m_mem = nullptr;
    return *this;
  }
  // Creates a buffer of `bytes`, copying `host` into it when non-null.
  static Result<Buffer> create(Runtime& rt, size_t bytes, const void* host, cl_mem_flags flags);
  // Wraps caller memory (CL_MEM_USE_HOST_PTR): zero-copy on CPU devices such as PoCL, so large
  // results land in their destination without a fresh allocation and a second copy.
  static Result<Buffer> wrap(Runtime& rt, size_t bytes, void* host, cl_mem_flags flags);
  // Makes the device's writes to a wrapped buffer visible in host memory (map + unmap).
  Status sync_to_host(cl_command_queue q, size_t bytes) const;
  cl_mem get() const { return m_mem; }
  void reset() {
    if (m_mem) clReleaseMemObject(m_mem);
    m_mem = nullptr;
  }

 private:
  cl_mem m_mem = nullptr;
};

}  // namespace btfc::ocl

// Returns a device_error naming `what` and the CL error from the enclosing function (returning
// Status or Result) when an OpenCL call fails.
#define BTFC_CL_CHECK(call, what)                                                                                    \
  do {                                                                                                               \
    const cl_int e_ = (call);                                                                                        \
    if (e_ != CL_SUCCESS)                                                                                            \
      return ::btfc::Status(::btfc::StatusCode::device_error, std::string(what) + ": " + ::btfc::ocl::cl_error_name(e_)); \
  } while (0)
