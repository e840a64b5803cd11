#include "core/sysinfo.h"

#include "core/cpu_dispatch.h"

#include <unistd.h>

#include <cstdio>
#include <fstream>
#include <sstream>
#include <thread>

namespace btfc {
namespace {

// Value in kB of a "Key:   1234 kB" line of a /proc file, or 0.
uint64_t proc_kb(const char* file, const std::string& key) {
  std::ifstream in(file);
  std::string line;
  while (std::getline(in, line))
    if (line.compare(0, key.size(), key) == 0 && line.size() > key.size() && line[key.size()] == ':')
      return std::strtoull(line.c_str() + key.size() + 1, nullptr, 10);
  return 0;
}

}  // namespace

uint64_t peak_rss_bytes() { return proc_kb("/proc/self/status", "VmHWM") * 1024; }
uint64_t current_rss_bytes() { return proc_kb("/proc/self/status", "VmRSS") * 1024; }

bool reset_peak_rss() {
  std::FILE* f = std::fopen("/proc/self/clear_refs", "w");
  if (!f) return false;
  const bool ok = std::fputs("5", f) >= 0;
  return std::fclose(f) == 0 && ok;
}

std::string machine_summary() {
  std::string cpu = "unknown CPU";
  std::ifstream in("/proc/cpuinfo");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("model name", 0) == 0) {
      const size_t colon = line.find(':');
      if (colon != std::string::npos) cpu = line.substr(colon + 2);
      break;
    }
  const uint64_t mem_kb = proc_kb("/proc/meminfo", "MemTotal");
  std::ostringstream s;
  s << cpu << ", " << std::thread::hardware_concurrency() << " cores";
  if (mem_kb) {
    char buf[32];
    std::snprintf(buf, sizeof buf, ", %.1f GiB", double(mem_kb) / (1024.0 * 1024.0));
    s << buf;
  }
  s << ", loops " << cpu_dispatch_level();
  return s.str();
}

bool cpu_has_avx512f() {
#if defined(__x86_64__) && defined(__GNUC__)
  static const bool yes = [] {
    __builtin_cpu_init();
    return __builtin_cpu_supports("avx512f");
  }();
  return yes;
#else
  return false;
#endif
}

bool cpu_is_intel() {
#if defined(__x86_64__) && defined(__GNUC__)
  static const bool yes = [] {
    __builtin_cpu_init();
    return __builtin_cpu_is("intel") != 0;
  }();
  return yes;
#else
  return false;
#endif
}

bool cpu_is_zen1() {
#if defined(__x86_64__) && defined(__GNUC__)
  static const bool yes = [] {
    __builtin_cpu_init();
    return __builtin_cpu_is("znver1") != 0;
  }();
  return yes;
#else
  return false;
#endif
}

bool cpu_has_avx2_fma() {
#if defined(__x86_64__) && defined(__GNUC__)
  static const bool yes = [] {
    __builtin_cpu_init();
    return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
  }();
  return yes;
#else
  return false;
#endif
}

const char* cpu_dispatch_level() {
#if BTFC_CPU_DISPATCH
  // The same order as the ifunc resolver of BTFC_CPU_CLONES tries them.
  if (__builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512bw") && __builtin_cpu_supports("avx512vl") &&
      __builtin_cpu_supports("avx512dq") && __builtin_cpu_supports("avx512cd"))
    return "x86-64-v4 (AVX-512)";
  if (__builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma") && __builtin_cpu_supports("bmi2")) return "x86-64-v3 (AVX2)";
  return "x86-64 baseline";
#else
  return "as built (no run-time dispatch)";
#endif
}

}  // namespace btfc
