// The OpenCL-free half of the runtime: the device choice, the one-time fallback warning, kernel
// sources and the summary. Compiled in every configuration; the device half is cl_device.cpp
// (BTFC_OPENCL=ON) or cl_none.cpp (OFF). See cl_runtime.h.
#include "core/cl_runtime.h"

#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <mutex>
#include <set>
#include <sstream>

namespace btfc::ocl {

// Generated at build time from kernels/*.cl and kernels/btfc_shared.h (kernels/embed.cmake).
const char* embedded_kernel(const std::string& file);

namespace {

std::atomic<int> g_choice{-1};
std::mutex g_mutex;
std::string g_fallback_reason;
std::set<std::string> g_warned;

// Once per distinct reason (a loop over chunks that fails the same way warns once; a later,
// different failure, e.g. another kernel's build, is still said), at most k_max_warnings.
constexpr size_t k_max_warnings = 8;
void warn_once(const std::string& reason) {
  std::lock_guard<std::mutex> lock(g_mutex);
  g_fallback_reason = reason;
  if (g_warned.size() < k_max_warnings && g_warned.insert(reason).second)
    std::fprintf(stderr, "warning: %s\n", g_fallback_reason.c_str());
}

}  // namespace

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

Result<Runtime*> Runtime::get() {
  const DeviceChoice c = device_choice();
  // Checked on every call (tests switch the choice within one process): `cpu` loads nothing.
  if (c == DeviceChoice::cpu) return Status(StatusCode::device_error, "OpenCL not used: CPU path chosen (--device cpu or BTFC_FORCE_CPU=1)");
  auto r = create();
  if (!r.ok() && c == DeviceChoice::cl)
    return Status(r.status().code(), "OpenCL required (--device cl) but unavailable: " + r.status().message());
  return r;
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

bool use_opencl(std::string* why) {
  const DeviceChoice c = device_choice();
  if (c == DeviceChoice::cpu) {
    if (why) *why = "CPU path chosen (--device cpu or BTFC_FORCE_CPU=1)";
    return false;
  }
  if (c == DeviceChoice::cl) return true;
  auto rt = Runtime::get();
  if (rt.ok()) return true;
  warn_once("OpenCL unavailable, running the CPU path: " + rt.status().message());
  if (why) *why = fallback_reason();
  return false;
}

bool fall_back_after(const Status& s) {
  if (device_choice() != DeviceChoice::automatic) return false;
  warn_once("OpenCL failed, running the CPU path: " + s.message());
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

}  // namespace btfc::ocl
