// The OpenCL side of the runtime (BTFC_OPENCL=ON): devices, context, queues, programs, kernels
// and buffers, every call through the dlopen()ed table of core/cl_api.h. See cl_runtime.h.
#include <cstdlib>
#include <map>
#include <mutex>
#include <string>
#include <vector>

#include "core/cl_api.h"
#include "core/cl_runtime.h"

namespace btfc::ocl {

struct Runtime::Impl {
  cl_platform_id platform = nullptr;
  cl_device_id device = nullptr;
  cl_context context = nullptr;
};

namespace {

// "CL_OUT_OF_RESOURCES (-5)"
std::string error_name(cl_int err) {
  const char* n = nullptr;
  switch (err) {
    case CL_SUCCESS: n = "CL_SUCCESS"; break;
    case CL_DEVICE_NOT_FOUND: n = "CL_DEVICE_NOT_FOUND"; break;
    case CL_OUT_OF_RESOURCES: n = "CL_OUT_OF_RESOURCES"; break;
    case CL_OUT_OF_HOST_MEMORY: n = "CL_OUT_OF_HOST_MEMORY"; break;
    case CL_MEM_OBJECT_ALLOCATION_FAILURE: n = "CL_MEM_OBJECT_ALLOCATION_FAILURE"; break;
    case CL_BUILD_PROGRAM_FAILURE: n = "CL_BUILD_PROGRAM_FAILURE"; break;
    case CL_INVALID_VALUE: n = "CL_INVALID_VALUE"; break;
    case CL_INVALID_KERNEL_NAME: n = "CL_INVALID_KERNEL_NAME"; break;
    case CL_INVALID_KERNEL_ARGS: n = "CL_INVALID_KERNEL_ARGS"; break;
    case CL_INVALID_WORK_GROUP_SIZE: n = "CL_INVALID_WORK_GROUP_SIZE"; break;
    case CL_INVALID_BUFFER_SIZE: n = "CL_INVALID_BUFFER_SIZE"; break;
    case -1001: n = "CL_PLATFORM_NOT_FOUND_KHR"; break;  // the ICD loader found no driver
    default: n = "CL error";
  }
  return std::string(n) + " (" + std::to_string(err) + ")";
}

Status failed(const std::string& what, cl_int err) { return Status(StatusCode::device_error, what + ": " + error_name(err)); }

// `cpu` never loads the library (cl_runtime.h): checked on every call, not cached, because tests
// switch the choice within one process.
Result<const Api*> loaded_api() {
  if (device_choice() == DeviceChoice::cpu)
    return Status(StatusCode::device_error, "OpenCL not loaded: CPU path chosen (--device cpu or BTFC_FORCE_CPU=1)");
  return api();
}

std::string info_string(const Api& cl, cl_device_id d, cl_device_info what) {
  size_t n = 0;
  if (cl.clGetDeviceInfo(d, what, 0, nullptr, &n) != CL_SUCCESS || n == 0) return "";
  std::string s(n, '\0');
  cl.clGetDeviceInfo(d, what, n, s.data(), nullptr);
  while (!s.empty() && s.back() == '\0') s.pop_back();
  return s;
}

struct Found {
  cl_platform_id platform;
  cl_device_id device;
  DeviceInfo info;
};

Result<std::vector<Found>> enumerate(const Api& cl) {
  cl_uint np = 0;
  cl_int err = cl.clGetPlatformIDs(0, nullptr, &np);
  if (err != CL_SUCCESS || np == 0) return Status(StatusCode::device_error, "no OpenCL platform (" + error_name(err) + ")");
  std::vector<cl_platform_id> platforms(np);
  cl.clGetPlatformIDs(np, platforms.data(), nullptr);
  std::vector<Found> out;
  for (cl_platform_id p : platforms) {
    char pname[256] = {0};
    cl.clGetPlatformInfo(p, CL_PLATFORM_NAME, sizeof(pname) - 1, pname, nullptr);
    cl_uint nd = 0;
    if (cl.clGetDeviceIDs(p, CL_DEVICE_TYPE_ALL, 0, nullptr, &nd) != CL_SUCCESS || nd == 0) continue;
    std::vector<cl_device_id> devs(nd);
    cl.clGetDeviceIDs(p, CL_DEVICE_TYPE_ALL, nd, devs.data(), nullptr);
    for (cl_device_id d : devs) {
      Found f{p, d, {}};
      f.info.platform = pname;
      f.info.name = info_string(cl, d, CL_DEVICE_NAME);
      f.info.version = info_string(cl, d, CL_DEVICE_VERSION);
      cl_device_type t = 0;
      cl.clGetDeviceInfo(d, CL_DEVICE_TYPE, sizeof(t), &t, nullptr);
      f.info.type = (t & CL_DEVICE_TYPE_GPU) ? "gpu" : (t & CL_DEVICE_TYPE_CPU) ? "cpu" : "other";
      cl_uint cu = 0;
      cl.clGetDeviceInfo(d, CL_DEVICE_MAX_COMPUTE_UNITS, sizeof(cu), &cu, nullptr);
      f.info.compute_units = int(cu);
      cl_ulong gm = 0, ma = 0;
      cl.clGetDeviceInfo(d, CL_DEVICE_GLOBAL_MEM_SIZE, sizeof(gm), &gm, nullptr);
      cl.clGetDeviceInfo(d, CL_DEVICE_MAX_MEM_ALLOC_SIZE, sizeof(ma), &ma, nullptr);
      f.info.global_mem = gm, f.info.max_alloc = ma;
      out.push_back(f);
    }
  }
  if (out.empty()) return Status(StatusCode::device_error, "OpenCL platforms found, but no device");
  return out;
}

// Per-thread state: queue and built kernels, keyed by "source folder|program/name". Only ever non-empty after
// the library was loaded, and the library is never unloaded, so the table is valid here.
struct ThreadState {
  cl_command_queue queue = nullptr;
  std::map<std::string, cl_kernel> kernels;
  ~ThreadState() {
    if (!api_loaded()) return;
    const Api& cl = *api().value();
    for (auto& [k, v] : kernels) cl.clReleaseKernel(v);
    if (queue) cl.clReleaseCommandQueue(queue);
  }
};
thread_local ThreadState t_state;

std::mutex g_mutex;
// Programs are built once per process and source folder, shared by all threads.
std::map<std::string, cl_program> g_programs;
Runtime::Impl* g_impl = nullptr;  // the one runtime's, for queue() below

Result<cl_command_queue> this_thread_queue() {
  if (!t_state.queue) {
    if (!g_impl) return Status(StatusCode::device_error, "OpenCL runtime not created");
    BTFC_ASSIGN_OR_RETURN(const Api* cl, api());
    cl_int err = CL_SUCCESS;
    t_state.queue = cl->clCreateCommandQueue(g_impl->context, g_impl->device, 0, &err);
    if (err != CL_SUCCESS) return failed("clCreateCommandQueue", err);
  }
  return t_state.queue;
}

}  // namespace

bool built_with_opencl() { return true; }
bool library_loaded() { return api_loaded(); }

Result<std::vector<DeviceInfo>> list_devices() {
  BTFC_ASSIGN_OR_RETURN(const Api* cl, loaded_api());
  BTFC_ASSIGN_OR_RETURN(std::vector<Found> found, enumerate(*cl));
  std::vector<DeviceInfo> out;
  for (const Found& f : found) out.push_back(f.info);
  return out;
}

Result<Runtime*> Runtime::create() {
  static std::mutex m;
  static Runtime* rt = nullptr;
  static Status failure;
  BTFC_ASSIGN_OR_RETURN(const Api* cl, loaded_api());
  std::lock_guard<std::mutex> lock(m);
  if (rt) return rt;
  if (!failure.ok()) return failure;
  auto found = enumerate(*cl);
  if (!found.ok()) return failure = found.status();
  const std::vector<Found>& fs = found.value();
  int pick = -1;
  if (const char* want = std::getenv("BTFC_CL_DEVICE"); want && *want) {
    char* end = nullptr;
    long idx = std::strtol(want, &end, 10);
    if (*end == '\0' && idx >= 0 && size_t(idx) < fs.size()) pick = int(idx);
    for (size_t i = 0; pick < 0 && i < fs.size(); ++i)
      if (fs[i].info.name.find(want) != std::string::npos) pick = int(i);
    if (pick < 0) return failure = Status(StatusCode::device_error, std::string("BTFC_CL_DEVICE=") + want + " matches no OpenCL device");
  }
  for (size_t i = 0; pick < 0 && i < fs.size(); ++i)
    if (fs[i].info.type == "gpu") pick = int(i);
  if (pick < 0) pick = 0;
  auto impl = new Impl{fs[pick].platform, fs[pick].device, nullptr};
  cl_int err = CL_SUCCESS;
  impl->context = cl->clCreateContext(nullptr, 1, &impl->device, nullptr, nullptr, &err);
  if (err != CL_SUCCESS) {
    delete impl;
    return failure = failed("clCreateContext failed", err);
  }
  auto* r = new Runtime();
  r->m_info = fs[pick].info;
  r->m_impl = impl;
  g_impl = impl;  // published before rt: other threads reach it only through rt, under m
  rt = r;  // lives for the process: OpenCL objects are torn down by the driver at exit
  return rt;
}

// The programs' source folder: BTFC_KERNEL_DIR (a developer's edited kernels) or "" (the
// embedded ones). Part of the caches' keys, so a process that switches it (the broken-kernel
// tests, after other OpenCL tests in the same process) builds from the folder it now names.
static std::string kernel_dir() {
  const char* dir = std::getenv("BTFC_KERNEL_DIR");
  return dir ? dir : "";
}

Result<Kernel> Runtime::kernel(const std::string& program, const std::string& name) {
  const std::string program_key = kernel_dir() + "|" + program, key = program_key + "/" + name;
  Kernel out;
  if (auto it = t_state.kernels.find(key); it != t_state.kernels.end()) {
    out.m_kernel = it->second;
    return out;
  }
  BTFC_ASSIGN_OR_RETURN(const Api* cl, api());
  cl_program prog = nullptr;
  {
    std::lock_guard<std::mutex> lock(g_mutex);
    if (auto it = g_programs.find(program_key); it != g_programs.end()) {
      prog = it->second;
    } else {
      BTFC_ASSIGN_OR_RETURN(std::string src, kernel_source(program));
      const char* s = src.c_str();
      cl_int err = CL_SUCCESS;
      prog = cl->clCreateProgramWithSource(m_impl->context, 1, &s, nullptr, &err);
      if (err != CL_SUCCESS) return failed("clCreateProgramWithSource(" + program + ")", err);
      err = cl->clBuildProgram(prog, 1, &m_impl->device, "-cl-std=CL1.2 -cl-fast-relaxed-math -cl-mad-enable", nullptr, nullptr);
      if (err != CL_SUCCESS) {
        size_t n = 0;
        cl->clGetProgramBuildInfo(prog, m_impl->device, CL_PROGRAM_BUILD_LOG, 0, nullptr, &n);
        std::string log(n, '\0');
        cl->clGetProgramBuildInfo(prog, m_impl->device, CL_PROGRAM_BUILD_LOG, n, log.data(), nullptr);
        cl->clReleaseProgram(prog);
        return Status(StatusCode::device_error, "building OpenCL program " + program + ".cl failed (" + error_name(err) +
                                                    "); compiler log:\n" + log);
      }
      g_programs[program_key] = prog;
    }
  }
  cl_int err = CL_SUCCESS;
  cl_kernel k = cl->clCreateKernel(prog, name.c_str(), &err);
  if (err != CL_SUCCESS) return failed("clCreateKernel(" + key + ")", err);
  t_state.kernels[key] = k;
  out.m_kernel = k;
  return out;
}

Status Kernel::raw_arg(int i, size_t bytes, const void* value) {
  BTFC_ASSIGN_OR_RETURN(const Api* cl, api());
  const cl_int e = cl->clSetKernelArg(static_cast<cl_kernel>(m_kernel), cl_uint(i), bytes, value);
  if (e != CL_SUCCESS) return failed("clSetKernelArg(" + std::to_string(i) + ")", e);
  return {};
}

Status Kernel::arg(int i, int32_t v) { return raw_arg(i, sizeof(cl_int), &v); }
Status Kernel::arg(int i, float v) { return raw_arg(i, sizeof(cl_float), &v); }
Status Kernel::arg(int i, const Buffer& b) {
  const cl_mem m = static_cast<cl_mem>(b.m_mem);
  return raw_arg(i, sizeof(cl_mem), &m);
}

Status Kernel::launch(int dims, const size_t* global, const size_t* local, const char* what) const {
  BTFC_ASSIGN_OR_RETURN(const Api* cl, api());
  BTFC_ASSIGN_OR_RETURN(cl_command_queue q, this_thread_queue());
  const cl_int e = cl->clEnqueueNDRangeKernel(q, static_cast<cl_kernel>(m_kernel), cl_uint(dims), nullptr, global, local, 0, nullptr, nullptr);
  if (e != CL_SUCCESS) return failed(what, e);
  return {};
}

namespace {

cl_mem_flags flags_of(Access a) {
  return a == Access::read_only ? CL_MEM_READ_ONLY : a == Access::write_only ? CL_MEM_WRITE_ONLY : CL_MEM_READ_WRITE;
}

Status check_size(const Runtime& rt, size_t bytes) {
  if (bytes > rt.info().max_alloc)
    return Status(StatusCode::device_error, "OpenCL buffer of " + std::to_string(bytes) + " bytes exceeds the device's maximum allocation of " +
                                                std::to_string(rt.info().max_alloc));
  return {};
}

}  // namespace

Result<Buffer> Buffer::create(Runtime& rt, size_t bytes, const void* host, Access access) {
  BTFC_RETURN_IF_ERROR(check_size(rt, bytes));
  BTFC_ASSIGN_OR_RETURN(const Api* cl, api());
  cl_int err = CL_SUCCESS;
  Buffer b;
  b.m_mem = cl->clCreateBuffer(rt.m_impl->context, flags_of(access) | (host ? CL_MEM_COPY_HOST_PTR : 0), bytes ? bytes : 4,
                               const_cast<void*>(host), &err);
  if (err != CL_SUCCESS) return failed("clCreateBuffer(" + std::to_string(bytes) + " bytes)", err);
  return b;
}

Result<Buffer> Buffer::wrap(Runtime& rt, size_t bytes, void* host, Access access) {
  BTFC_RETURN_IF_ERROR(check_size(rt, bytes));
  BTFC_ASSIGN_OR_RETURN(const Api* cl, api());
  cl_int err = CL_SUCCESS;
  Buffer b;
  b.m_mem = cl->clCreateBuffer(rt.m_impl->context, flags_of(access) | CL_MEM_USE_HOST_PTR, bytes, host, &err);
  if (err != CL_SUCCESS) return failed("clCreateBuffer(USE_HOST_PTR, " + std::to_string(bytes) + " bytes)", err);
  return b;
}

Status Buffer::sync_to_host(size_t bytes) const {
  BTFC_ASSIGN_OR_RETURN(const Api* cl, api());
  BTFC_ASSIGN_OR_RETURN(cl_command_queue q, this_thread_queue());
  const cl_mem mem = static_cast<cl_mem>(m_mem);
  cl_int err = CL_SUCCESS;
  void* p = cl->clEnqueueMapBuffer(q, mem, CL_TRUE, CL_MAP_READ, 0, bytes, 0, nullptr, nullptr, &err);
  if (err != CL_SUCCESS) return failed("clEnqueueMapBuffer", err);
  err = cl->clEnqueueUnmapMemObject(q, mem, p, 0, nullptr, nullptr);
  if (err == CL_SUCCESS) err = cl->clFinish(q);
  if (err != CL_SUCCESS) return failed("clEnqueueUnmapMemObject", err);
  return {};
}

void Buffer::reset() {
  // A buffer exists only after the library was loaded (create / wrap), so the table is there.
  if (m_mem) (*api().value()).clReleaseMemObject(static_cast<cl_mem>(m_mem));
  m_mem = nullptr;
}

}  // namespace btfc::ocl
