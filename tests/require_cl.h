// REQUIRE_CL(): skips an OpenCL comparison test (with the reason) when the CPU path is forced
// (BTFC_FORCE_CPU=1, scripts/test.sh's second pass) or no OpenCL device works.
#pragma once
#include <gtest/gtest.h>

#include <string>

#include "core/cl_runtime.h"

namespace btfc::test {

inline bool have_cl(std::string* why) {
  if (ocl::device_choice() == ocl::DeviceChoice::cpu) {
    *why = "BTFC_FORCE_CPU=1: OpenCL comparisons skipped, CPU path only";
    return false;
  }
  auto rt = ocl::Runtime::get();
  if (!rt.ok()) *why = "no OpenCL device: " + rt.status().message();
  return rt.ok();
}

}  // namespace btfc::test

#define REQUIRE_CL()                                       \
  do {                                                     \
    std::string why_;                                      \
    if (!btfc::test::have_cl(&why_)) GTEST_SKIP() << why_; \
  } while (0)
