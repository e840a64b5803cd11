// The OpenCL C API as a table of function pointers, filled from the OpenCL library loaded with
// dlopen() on first use. Internal to the runtime (core/cl_device.cpp); everything else goes
// through core/cl_runtime.h.
//
// Why a table and not -lOpenCL: a bare `btfc` process (help, codecs, --device cpu, every CPU-only
// job) then maps no OpenCL library, driver or LLVM, and a machine without an ICD loader still runs
// the CPU path. Why members and not global `clXxx` definitions: global symbols of those names
// would interpose the ICD loader's (or PoCL's) own inside the process.
//
// BTFC_OPENCL_LIBRARY=<path or soname> loads that library instead of libOpenCL.so.1 (tests use a
// path that does not exist to check the fallback).
#pragma once
#define CL_TARGET_OPENCL_VERSION 120
#include <CL/cl.h>

#include "core/status.h"

namespace btfc::ocl {

// Every OpenCL function btfc calls. Adding a call means adding its name here.
#define BTFC_CL_FUNCTIONS(X)                                                                      \
  X(clGetPlatformIDs) X(clGetPlatformInfo) X(clGetDeviceIDs) X(clGetDeviceInfo) X(clCreateContext) \
  X(clCreateCommandQueue) X(clReleaseCommandQueue) X(clCreateProgramWithSource) X(clBuildProgram) \
  X(clGetProgramBuildInfo) X(clReleaseProgram) X(clCreateKernel) X(clReleaseKernel)               \
  X(clSetKernelArg) X(clCreateBuffer) X(clReleaseMemObject) X(clEnqueueNDRangeKernel)             \
  X(clEnqueueMapBuffer) X(clEnqueueUnmapMemObject) X(clFinish)

struct Api {
#define BTFC_CL_MEMBER(f) decltype(&::f) f = nullptr;
  BTFC_CL_FUNCTIONS(BTFC_CL_MEMBER)
#undef BTFC_CL_MEMBER
};

// The table, loading the library on the first call (thread-safe, once per process). Errors name
// the library and the reason (not found, or a missing function); the outcome is cached.
Result<const Api*> api();
// Whether api() has loaded the library in this process.
bool api_loaded();

}  // namespace btfc::ocl
