// Facts about the running process and machine, for benchmark reports.
//
// Peak memory is the kernel's resident-set high-water mark (VmHWM in /proc/self/status).
// reset_peak_rss() writes "5" to /proc/self/clear_refs (Linux >= 4.0), which resets that mark, so
// a benchmark can report the peak of each run separately. Where /proc is missing the functions
// answer 0 / do nothing (and peak_rss_resettable() says so), never fail.
#pragma once
#include <cstdint>
#include <string>

namespace btfc {

uint64_t peak_rss_bytes();
uint64_t current_rss_bytes();
bool reset_peak_rss();  // true when the high-water mark was reset

// "Intel(R) Xeon(R) ... , 2 cores, 23.4 GiB, loops x86-64-v3 (AVX2)" from /proc/cpuinfo, sysconf,
// /proc/meminfo and the run-time dispatch of the hot loops (core/cpu_dispatch.h).
std::string machine_summary();

}  // namespace btfc
