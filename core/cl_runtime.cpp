// OpenCL runtime; see cl_runtime.h for the contract.
#include "core/cl_runtime.h"

#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <mutex>
#include <sstream>

namespace btfc::ocl {

// Generated at build time from kernels/*.cl and kernels/btfc_shared.h (kernels/embed.cmake).
const char* embedded_kernel(const std::string& file);

namespace {

std::atomic<int> g_choice{-1};
std::mutex g_mutex;
std::string g_fallback_reason;
bool g_warned = false;

std::string info_string(cl_device_id d, cl_device_info what) {
  size_t n = 0;
  if (clGetDeviceInfo(d, what, 0, nullptr, &n) != CL_SUCCESS || n == 0) return "";
  std::string s(n, '\0');
  clGetDeviceInfo(d, what, n, s.data(), nullptr);
  while (!s.empty() && s.back() == '\0') s.pop_back();
  return s;
}

struct Found {
  cl_platform_id platform;
  cl_device_id device;
  DeviceInfo info;
};

Result<std::vector<Found>> enumerate() {
  cl_uint np = 0;
  cl_int err = clGetPlatformIDs(0, nullptr, &np);
  if (err != CL_SUCCESS || np == 0) return Status(StatusCode::device_error, "no OpenCL platform (" + cl_error_name(err) + ")");
  std::vector<cl_platform_id> platforms(np);
  clGetPlatformIDs(np, platforms.data(), nullptr);
  std::vector<Found> out;
  for (cl_platform_id p : platforms) {
    char pname[256] = {0};
    clGetPlatformInfo(p, CL_PLATFORM_NAME, sizeof(pname) - 1, pname, nullptr);
    cl_uint nd = 0;
    if (clGetDeviceIDs(p, CL_DEVICE_TYPE_ALL, 0, nullptr, &nd) != CL_SUCCESS || nd == 0) continue;
    std::vector<cl_device_id> devs(nd);
    clGetDeviceIDs(p, CL_DEVICE_TYPE_ALL, nd, devs.data(), nullptr);
    for (cl_device_id d : devs) {
      Found f{p, d, {}};
      f.info.platform = pname;
      f.info.name = info_string(d, CL_DEVICE_NAME);
      f.info.version = info_string(d, CL_DEVICE_VERSION);
      cl_device_type t = 0;
      clGetDeviceInfo(d, CL_DEVICE_TYPE, sizeof(t), &t, nullptr);
      f.info.type = (t & CL_DEVICE_TYPE_GPU) ? "gpu" : (t & CL_DEVICE_TYPE_CPU) ? "cpu" : "other";
      cl_uint cu = 0;
      clGetDeviceInfo(d, CL_DEVICE_MAX_COMPUTE_UNITS, sizeof(cu), &cu, nullptr);
      f.info.compute_units = int(cu);
      cl_ulong gm = 0, ma = 0;
      clGetDeviceInfo(d, CL_DEVICE_GLOBAL_MEM_SIZE, sizeof(gm), &gm, nullptr);
      clGetDeviceInfo(d, CL_DEVICE_MAX_MEM_ALLOC_SIZE, sizeof(ma), &ma, nullptr);
      f.info.global_mem = gm, f.info.max_alloc = ma;
      out.push_back(f);
    }
  }
  if (out.empty()) return Status(StatusCode::device_error, "OpenCL platforms found, but no device");
  return out;
}

// Per-thread state: queue and built kernels, keyed by "program/name".
struct ThreadState {
  cl_command_queue queue = nullptr;
  std::map<std::string, cl_kernel> kernels;
  ~ThreadState() {
    for (auto& [k, v] : kernels) clReleaseKernel(v);
    if (queue) clReleaseCommandQueue(queue);
  }
};
thread_local ThreadState t_state;

// Programs are built once per process and shared by all threads.
std::map<std::string, cl_program> g_programs;

}  // namespace

std::string cl_error_name(cl_int err) {
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
    default: n = "CL error";
  }
  return std::string(n) + " (" + std::to_string(err) + ")";
}

void set_device_choice(DeviceChoice c) { g_choice = int(c); }

DeviceChoice device_choice() {
  int c = g_choice.load();
  if (c < 0) {
    const char* f = std::getenv("BTFC_FORCE_CPU");
    return (f && std::string(f) == "1") ? DeviceChoice::cpu : DeviceChoice::automatic;
  }
  return DeviceChoice(c);
}

Result<DeviceChoice> parse_device_choice(const std::string& s) {
  if (s == "auto") return DeviceChoice::automatic;
  if (s == "cpu") return DeviceChoice::cpu;
  if (s == "cl") return DeviceChoice::cl;
  return invalid_argument("--device " + s + ": expected cpu, cl or auto");
}

Result<std::vector<DeviceInfo>> list_devices() {
  BTFC_ASSIGN_OR_RETURN(std::vector<Found> found, enumerate());
  std::vector<DeviceInfo> out;
  for (const Found& f : found) out.push_back(f.info);
  return out;
}

Result<Runtime*> Runtime::get() {
  static std::mutex m;
  static Runtime* rt = nullptr;
  static Status failure;
  std::lock_guard<std::mutex> lock(m);
  if (rt) return rt;
  if (!failure.ok()) return failure;
  auto found = enumerate();
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
  auto* r = new Runtime();
  r->m_platform = fs[pick].platform;
  r->m_device = fs[pick].device;
  r->m_info = fs[pick].info;
  cl_int err = CL_SUCCESS;
  r->m_context = clCreateContext(nullptr, 1, &r->m_device, nullptr, nullptr, &err);
  if (err != CL_SUCCESS) {
    delete r;
    return failure = Status(StatusCode::device_error, "clCreateContext failed: " + cl_error_name(err));
  }
  rt = r;  // lives for the process: OpenCL objects are torn down by the driver at exit
  return rt;
}

Result<cl_command_queue> Runtime::queue() {
  if (!t_state.queue) {
    cl_int err = CL_SUCCESS;
    t_state.queue = clCreateCommandQueue(m_context, m_device, 0, &err);
    if (err != CL_SUCCESS) return Status(StatusCode::device_error, "clCreateCommandQueue failed: " + cl_error_name(err));
  }
  return t_state.queue;
}

Result<std::string> kernel_source(const std::string& program) {
  auto read = [](const std::string& file) -> Result<std::string> {
    if (const char* dir = std::getenv("BTFC_KERNEL_DIR"); dir && *dir) {
      std::ifstream in(std::string(dir) + "/" + file, std::ios::binary);
      if (!in) return io_error(std::string("BTFC_KERNEL_DIR: cannot read ") + dir + "/" + file);
      std::ostringstream ss;
      ss << in.rdbuf();
      return ss.str();
    }
    const char* src = embedded_kernel(file);
    if (!src) return Status(StatusCode::device_error, "no embedded kernel file " + file);
    return std::string(src);
  };
  BTFC_ASSIGN_OR_RETURN(std::string shared, read("btfc_shared.h"));
  BTFC_ASSIGN_OR_RETURN(std::string body, read(program + ".cl"));
  return shared + "\n#line 1 \"" + program + ".cl\"\n" + body;
}

Result<cl_kernel> Runtime::kernel(const std::string& program, const std::string& name) {
  const std::string key = program + "/" + name;
  if (auto it = t_state.kernels.find(key); it != t_state.kernels.end()) return it->second;
  cl_program prog = nullptr;
  {
    std::lock_guard<std::mutex> lock(g_mutex);
    if (auto it = g_programs.find(program); it != g_programs.end()) {
      prog = it->second;
    } else {
      BTFC_ASSIGN_OR_RETURN(std::string src, kernel_source(program));
      const char* s = src.c_str();
      cl_int err = CL_SUCCESS;
      prog = clCreateProgramWithSource(m_context, 1, &s, nullptr, &err);
      if (err != CL_SUCCESS) return Status(StatusCode::device_error, "clCreateProgramWithSource(" + program + "): " + cl_error_name(err));
      err = clBuildProgram(prog, 1, &m_device, "-cl-std=CL1.2 -cl-fast-relaxed-math -cl-mad-enable", nullptr, nullptr);
      if (err != CL_SUCCESS) {
        size_t n = 0;
        clGetProgramBuildInfo(prog, m_device, CL_PROGRAM_BUILD_LOG, 0, nullptr, &n);
        std::string log(n, '\0');
        clGetProgramBuildInfo(prog, m_device, CL_PROGRAM_BUILD_LOG, n, log.data(), nullptr);
        clReleaseProgram(prog);
        return Status(StatusCode::device_error, "building OpenCL program " + program + ".cl failed (" + cl_error_name(err) +
                                                    "); compiler log:\n" + log);
      }
      g_programs[program] = prog;
    }
  }
  cl_int err = CL_SUCCESS;
  cl_kernel k = clCreateKernel(prog, name.c_str(), &err);
  if (err != CL_SUCCESS) return Status(StatusCode::device_error, "clCreateKernel(" + key + "): " + cl_error_name(err));
  t_state.kernels[key] = k;
  return k;
}

bool use_opencl(std::string* why) {
  const DeviceChoice c = device_choice();
  if (c == DeviceChoice::cpu) {
    if (why) *why = "CPU path chosen (--device cpu or BTFC_FORCE_CPU=1)";
    return false;
  }
  if (c == DeviceChoice::cl) return true;
  auto rt = Runtime::get();
  if (rt.ok()) return true;
  std::lock_guard<std::mutex> lock(g_mutex);
  g_fallback_reason = "OpenCL unavailable, running the CPU path: " + rt.status().message();
  if (!g_warned) {
    std::fprintf(stderr, "warning: %s\n", g_fallback_reason.c_str());
    g_warned = true;
  }
  if (why) *why = g_fallback_reason;
  return false;
}

bool fall_back_after(const Status& s) {
  if (device_choice() != DeviceChoice::automatic) return false;
  std::lock_guard<std::mutex> lock(g_mutex);
  g_fallback_reason = "OpenCL failed, running the CPU path: " + s.message();
  if (!g_warned) {
    std::fprintf(stderr, "warning: %s\n", g_fallback_reason.c_str());
    g_warned = true;
  }
  return true;
}

std::string fallback_reason() {
  std::lock_guard<std::mutex> lock(g_mutex);
  return g_fallback_reason;
}

std::string device_summary() {
  const std::string why = fallback_reason();
  if (!why.empty()) return "cpu: " + why;
  if (device_choice() == DeviceChoice::cpu) return "cpu: CPU path chosen (--device cpu or BTFC_FORCE_CPU=1)";
  auto rt = Runtime::get();
  return rt.ok() ? "opencl: " + rt.value()->info().name : "cpu: " + rt.status().message();
}

Result<Buffer> Buffer::create(Runtime& rt, size_t bytes, const void* host, cl_mem_flags flags) {
  if (bytes > rt.info().max_alloc)
    return Status(StatusCode::device_error, "OpenCL buffer of " + std::to_string(bytes) + " bytes exceeds the device's maximum allocation of " +
                                                std::to_string(rt.info().max_alloc));
  cl_int err = CL_SUCCESS;
  Buffer b;
  b.m_mem = clCreateBuffer(rt.context(), flags | (host ? CL_MEM_COPY_HOST_PTR : 0), bytes ? bytes : 4, const_cast<void*>(host), &err);
  if (err != CL_SUCCESS) return Status(StatusCode::device_error, "clCreateBuffer(" + std::to_string(bytes) + " bytes): " + cl_error_name(err));
  return b;
}

Result<Buffer> Buffer::wrap(Runtime& rt, size_t bytes, void* host, cl_mem_flags flags) {
  if (bytes > rt.info().max_alloc)
    return Status(StatusCode::device_error, "OpenCL buffer of " + std::to_string(bytes) + " bytes exceeds the device's maximum allocation of " +
                                                std::to_string(rt.info().max_alloc));
  cl_int err = CL_SUCCESS;
  Buffer b;
  b.m_mem = clCreateBuffer(rt.context(), flags | CL_MEM_USE_HOST_PTR, bytes, host, &err);
  if (err != CL_SUCCESS) return Status(StatusCode::device_error, "clCreateBuffer(USE_HOST_PTR, " + std::to_string(bytes) + " bytes): " + cl_error_name(err));
  return b;
}

Status Buffer::sync_to_host(cl_command_queue q, size_t bytes) const {
  cl_int err = CL_SUCCESS;
  void* p = clEnqueueMapBuffer(q, m_mem, CL_TRUE, CL_MAP_READ, 0, bytes, 0, nullptr, nullptr, &err);
  if (err != CL_SUCCESS) return Status(StatusCode::device_error, "clEnqueueMapBuffer: " + cl_error_name(err));
  err = clEnqueueUnmapMemObject(q, m_mem, p, 0, nullptr, nullptr);
  if (err == CL_SUCCESS) err = clFinish(q);
  if (err != CL_SUCCESS) return Status(StatusCode::device_error, "clEnqueueUnmapMemObject: " + cl_error_name(err));
  return {};
}

}  // namespace btfc::ocl
