// The OpenCL runtime: device selection, one context, one queue per thread, programs built
// once per process and cached, kernels embedded at build time (kernels/*.cl), with a
// development override that loads them from disk.
//
// No OpenCL header or library is needed to use this header: btfc has no link-time OpenCL
// dependency. The OpenCL library (libOpenCL.so.1, the ICD loader; BTFC_OPENCL_LIBRARY=<path>
// overrides it) is dlopen()ed on the first call that needs a device (core/cl_api.h), never at
// process start and never under `cpu`. A build configured with BTFC_OPENCL=OFF compiles no
// OpenCL code at all (core/cl_none.cpp): every device call returns "built without OpenCL".
//
// Device choice (set once per process, e.g. by the CLI's --device):
//   cpu  - never touch OpenCL (the library is not even loaded); every kernel's C++ reference runs.
//   cl   - OpenCL is required; failures are errors (StatusCode::device_error).
//   auto - OpenCL when a device works, else warn (once per reason) on stderr and run the CPU path.
// BTFC_FORCE_CPU=1 forces `cpu` (the test suite's second pass). BTFC_CL_DEVICE picks a device by
// index ("1") or by a substring of its name ("pthread"); default: the first GPU, else the first
// device of any type (PoCL's CPU device here).
// BTFC_KERNEL_DIR=<dir> loads <dir>/<program>.cl and <dir>/btfc_shared.h instead of the embedded
// copies, so kernels can be edited without rebuilding. A failed build returns an error holding the
// full compiler log.
//
// Thread safety: get() and kernel() may be called from any thread; each thread gets its own
// kernel objects (OpenCL kernels are not thread-safe to set arguments on) and its own queue.
#pragma once
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "core/status.h"

namespace btfc::ocl {

enum class DeviceChoice { automatic, cpu, cl };
// Process-wide choice (default automatic, or cpu when BTFC_FORCE_CPU=1).
void set_device_choice(DeviceChoice c);
DeviceChoice device_choice();
Result<DeviceChoice> parse_device_choice(const std::string& s);  // "auto" | "cpu" | "cl"

// False when btfc was configured with BTFC_OPENCL=OFF (or without OpenCL headers).
bool built_with_opencl();
// True once this process has loaded the OpenCL library (tests: `cpu` must never load it).
bool library_loaded();

struct DeviceInfo {
  std::string platform, name, type, version;  // type: "gpu", "cpu" or "other"
  int compute_units = 0;
  unsigned long long global_mem = 0, max_alloc = 0;
};
// Every device of every platform, in selection-index order. Loads the OpenCL library; an error
// under `cpu`, when the library cannot be loaded, or in a build without OpenCL.
Result<std::vector<DeviceInfo>> list_devices();

class Buffer;

// One of this thread's kernels (Runtime::kernel). Arguments are set by index with the types the
// kernels declare (int, float, a buffer); launch() enqueues it on this thread's queue.
class Kernel {
 public:
  Status arg(int i, int32_t v);
  Status arg(int i, float v);
  Status arg(int i, const Buffer& b);
  template <class T>
  Status arg(int i, T v) = delete;  // size_t, double, bool...: say which 4-byte type the kernel takes
  // Sets arguments 0, 1, ... in order; stops at the first failure.
  template <class... A>
  Status args(const A&... a) {
    Status s;
    int i = 0;
    ((s.ok() ? (void)(s = arg(i++, a)) : (void)0), ...);
    return s;
  }
  // Enqueues a `dims`-dimensional range; `local` null lets the driver choose. `what` names the
  // kernel in errors.
  Status launch(int dims, const size_t* global, const size_t* local, const char* what) const;

 private:
  friend class Runtime;
  Status raw_arg(int i, size_t bytes, const void* value);
  void* m_kernel = nullptr;  // cl_kernel, owned by this thread's state (cl_device.cpp)
};

class Runtime {
 public:
  // The process's runtime, created on first use. Errors when OpenCL is unavailable (library
  // missing, no device, BTFC_OPENCL=OFF; under `cl` the message says OpenCL was required) and
  // under `cpu` (without loading anything).
  static Result<Runtime*> get();
  const DeviceInfo& info() const { return m_info; }
  // This thread's kernel `name` from program `program` (kernels/<program>.cl), built on first use.
  Result<Kernel> kernel(const std::string& program, const std::string& name);

  struct Impl;  // platform, device, context (cl_device.cpp)

 private:
  friend class Buffer;
  Runtime() = default;
  // The one runtime, or why there is none (cl_device.cpp; cl_none.cpp: "built without OpenCL").
  static Result<Runtime*> create();
  DeviceInfo m_info;
  Impl* m_impl = nullptr;
};

// Should this call use OpenCL? automatic: yes if the runtime works (else warns once, "no");
// cl: yes (errors surface later from get()); cpu: no. `why` receives the fallback reason.
bool use_opencl(std::string* why = nullptr);
// After an OpenCL path failed with `s`: under `auto`, records the reason, warns once per reason and returns
// true (run the CPU path); under `cl`, returns false (the caller reports `s`).
bool fall_back_after(const Status& s);
// The reason OpenCL was not used in this process ("" when it was, or was not asked for).
std::string fallback_reason();

// Source of kernels/<program>.cl with kernels/btfc_shared.h prepended (embedded or from
// BTFC_KERNEL_DIR).
Result<std::string> kernel_source(const std::string& program);

// Where this process's kernels ran, for statistics: "opencl: <device>", "cpu: <reason>".
std::string device_summary();

enum class Access { read_only, write_only, read_write };

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
  static Result<Buffer> create(Runtime& rt, size_t bytes, const void* host, Access access);
  // Wraps caller memory (CL_MEM_USE_HOST_PTR): zero-copy on CPU devices such as PoCL, so large
  // results land in their destination without a fresh allocation and a second copy.
  static Result<Buffer> wrap(Runtime& rt, size_t bytes, void* host, Access access);
  // Makes the device's writes to a wrapped buffer visible in host memory (map + unmap on this
  // thread's queue, then finish).
  Status sync_to_host(size_t bytes) const;
  void reset();

 private:
  friend class Kernel;
  void* m_mem = nullptr;  // cl_mem
};

}  // namespace btfc::ocl
