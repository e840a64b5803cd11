// The library as a BTFC_OPENCL=OFF build links it: btfc_core with the device half replaced by
// core/cl_none.cpp (tests/CMakeLists.txt). Built in every configuration, so a change that breaks
// the build without OpenCL fails here (a duplicate or missing symbol at link time, or these
// checks) without a second full build. The headers' side is checked by scripts/check_layers.py:
// only core/cl_api.h includes an OpenCL header.
#include <gtest/gtest.h>

#include <cstring>
#include <string>

#include "codecs/codec.h"
#include "core/cl_runtime.h"
#include "core/synth.h"

using namespace btfc;

namespace {

constexpr const char* k_not_built = "built without OpenCL";

Btf small_btf() {
  SynthOptions sp;
  sp.width = 9, sp.height = 7, sp.seed = 4;
  auto b = synthesize_btf(sp);
  EXPECT_TRUE(b.ok()) << b.status().message();
  return std::move(b).value();
}

Result<Btf> encode_decode(const Btf& b, const std::string& spec) {
  BTFC_ASSIGN_OR_RETURN(auto r, resolve_spec(spec));
  Context ctx;
  BTFC_ASSIGN_OR_RETURN(std::unique_ptr<Model> m, r.first->encode(b, r.second, ctx));
  Btf out;
  BTFC_RETURN_IF_ERROR(m->decode_all(out));
  return out;
}

}  // namespace

TEST(NoOpenCL, TheRuntimeSaysItWasBuiltWithout) {
  EXPECT_FALSE(ocl::built_with_opencl());
  ocl::set_device_choice(ocl::DeviceChoice::automatic);
  auto rt = ocl::Runtime::get();
  ASSERT_FALSE(rt.ok());
  EXPECT_NE(rt.status().message().find(k_not_built), std::string::npos) << rt.status().message();
  auto devs = ocl::list_devices();
  ASSERT_FALSE(devs.ok());
  EXPECT_NE(devs.status().message().find(k_not_built), std::string::npos);
  EXPECT_FALSE(ocl::library_loaded());
}

TEST(NoOpenCL, AutoRunsTheCppPathsAndSaysSoOnce) {
  const Btf b = small_btf();
  // Every codec whose encode or decode has kernels: fmf (decode), lpyr (pyramid), lpca
  // (assignment), mlvq (search when on a GPU, decode).
  std::string err;
  for (const char* spec : {"fmf:rank=4", "lpyr", "lpca:clusters=2:components=2", "mlvq"}) {
    ocl::set_device_choice(ocl::DeviceChoice::cpu);
    auto want = encode_decode(b, spec);
    ASSERT_TRUE(want.ok()) << spec << ": " << want.status().message();
    ocl::set_device_choice(ocl::DeviceChoice::automatic);
    testing::internal::CaptureStderr();
    auto got = encode_decode(b, spec);
    err += testing::internal::GetCapturedStderr();
    ASSERT_TRUE(got.ok()) << spec << ": " << got.status().message();
    ASSERT_EQ(got->size(), want->size());
    EXPECT_EQ(std::memcmp(got->data(), want->data(), want->size() * sizeof(float)), 0) << spec << ": the fallback is the CPU path";
  }
  // One warning for the process, whichever codec asked first.
  const std::string warning = std::string("warning: OpenCL unavailable, running the CPU path: ") + k_not_built;
  const size_t first = err.find(warning);
  EXPECT_NE(first, std::string::npos) << err;
  EXPECT_EQ(err.find("warning: OpenCL", first + 1), std::string::npos) << "warned more than once: " << err;
  EXPECT_NE(ocl::fallback_reason().find(k_not_built), std::string::npos);
  EXPECT_EQ(ocl::device_summary().rfind("cpu: ", 0), 0u) << ocl::device_summary();
  EXPECT_FALSE(ocl::library_loaded());
}

TEST(NoOpenCL, DeviceClIsAClearError) {
  ocl::set_device_choice(ocl::DeviceChoice::cl);
  auto r = encode_decode(small_btf(), "lpca:clusters=2:components=2");
  ocl::set_device_choice(ocl::DeviceChoice::automatic);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::device_error);
  EXPECT_NE(r.status().message().find(std::string("OpenCL required (--device cl) but unavailable: ") + k_not_built), std::string::npos)
      << r.status().message();
}
