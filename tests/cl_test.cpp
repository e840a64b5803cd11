// OpenCL kernels against their C++ references (kernels/fmf.cl vs codecs/fmf/fmf_cl.cpp), and the
// runtime's failure handling. Under BTFC_FORCE_CPU=1 (the suite's second pass) or without an
// OpenCL device the kernel comparisons are skipped and say so; everything else runs the CPU path.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>

#include "tests/require_cl.h"
#include "codecs/codec.h"
#include "codecs/fmf/fmf_cl.h"
#include "core/cl_runtime.h"
#include "core/synth.h"
#include "tests/cl_test_util.h"
#include "tests/test_paths.h"

using namespace btfc;

namespace {

using test::random_factors;
using test::rel_diff;

constexpr double k_tol = 1e-5;  // float rounding of C-term dot products, fast-relaxed-math exp

// dfmf factors of C components whose chroma blocks have own[1], own[2] (the rest zero padding,
// as FmfModel::packed lays them out); block_C is set when `told`.
fmf_cl::PackedFactors padded_chroma(int C, const int own[3], bool told, unsigned seed) {
  fmf_cl::PackedFactors f = random_factors(BTFC_FMF_DFMF, C, 11, 3, 19 * 7, seed);
  for (float& x : f.SxV) x *= 0.3f;
  for (int b = 1; b < 3; ++b) {
    for (int r = 0; r < f.rows_per_block; ++r)
      for (int k = own[b]; k < C; ++k) f.U[(size_t(b) * f.rows_per_block + r) * C + k] = 0.0f;
    for (int t = 0; t < f.texels; ++t)
      for (int k = own[b]; k < C; ++k) f.SxV[(size_t(b) * f.texels + t) * C + k] = 0.0f;
  }
  if (told) f.block_C = {own[0], own[1], own[2]};
  return f;
}

// Random interpolation queries over nL x nV directions (normalized weights).
std::vector<btfc_fmf_query> random_interp_queries(size_t n, int texels, int nL, int nV, std::mt19937& rng) {
  std::vector<btfc_fmf_query> iq(n);
  for (btfc_fmf_query& q : iq) {
    q.texel = int(rng() % texels);
    float sl = 0, sv = 0;
    for (int j = 0; j < 3; ++j) {
      q.light[j] = int(rng() % nL), q.view[j] = int(rng() % nV);
      q.wl[j] = float(rng() % 1000) / 1000.f, q.wv[j] = float(rng() % 1000) / 1000.f;
      sl += q.wl[j], sv += q.wv[j];
    }
    for (int j = 0; j < 3; ++j) q.wl[j] /= sl, q.wv[j] /= sv;
  }
  return iq;
}

}  // namespace

TEST(OpenCL, EvalKernelsMatchReference) {
  REQUIRE_CL();
  // Odd sizes, and query counts that are not multiples of the work-group size (64).
  for (int mode : {BTFC_FMF_RGB, BTFC_FMF_DFMF})
    for (int C : {1, 7, 32}) {
      const int nL = 13, nV = 5, texels = 37 * 11;
      fmf_cl::PackedFactors f = random_factors(mode, C, nL, nV, texels, unsigned(C + 10 * mode));
      if (mode == BTFC_FMF_DFMF)  // keep exp() of the log-luminance in a sane range
        for (float& x : f.SxV) x *= 0.3f;
      std::mt19937 rng(5);
      const size_t n = 1001;
      std::vector<fmf_cl::MeasuredQuery> mq(n);
      for (size_t i = 0; i < n; ++i) mq[i] = {int(rng() % texels), int(rng() % nL), int(rng() % nV), 0};
      const std::vector<btfc_fmf_query> iq = random_interp_queries(n, texels, nL, nV, rng);
      auto dev = fmf_cl::DeviceFactors::upload(f);
      ASSERT_TRUE(dev.ok()) << dev.status().message();
      std::vector<float> ref(3 * n), got(3 * n);
      fmf_cl::eval_measured_reference(f, mq, ref.data());
      ASSERT_TRUE(dev.value()->eval_measured(mq, got.data()).ok());
      EXPECT_LE(rel_diff(got, ref), k_tol) << "measured, mode " << mode << " C " << C;
      fmf_cl::eval_interp_reference(f, iq, ref.data());
      ASSERT_TRUE(dev.value()->eval_interp(iq, got.data()).ok());
      EXPECT_LE(rel_diff(got, ref), k_tol) << "interpolated, mode " << mode << " C " << C;
    }
  // dfmf chroma blocks of fewer components than the luminance's, zero-padded to C: with block_C
  // the kernels' dots stop at each block's own count (and would miss a component if they stopped
  // one short), without it they run over the padding; both match the padded reference.
  for (bool told : {true, false}) {
    const int C = 19, own[3] = {C, 9, 1};
    const fmf_cl::PackedFactors f = padded_chroma(C, own, told, 77);
    std::mt19937 rng(9);
    const size_t n = 333;
    std::vector<fmf_cl::MeasuredQuery> mq(n);
    for (size_t i = 0; i < n; ++i) mq[i] = {int(rng() % f.texels), int(rng() % f.nL), int(rng() % f.nV), 0};
    const std::vector<btfc_fmf_query> iq = random_interp_queries(n, f.texels, f.nL, f.nV, rng);
    auto dev = fmf_cl::DeviceFactors::upload(f);
    ASSERT_TRUE(dev.ok()) << dev.status().message();
    std::vector<float> ref(3 * n), got(3 * n);
    fmf_cl::eval_measured_reference(f, mq, ref.data());
    ASSERT_TRUE(dev.value()->eval_measured(mq, got.data()).ok());
    EXPECT_LE(rel_diff(got, ref), k_tol) << "measured, padded chroma, block_C " << (told ? "given" : "empty");
    fmf_cl::eval_interp_reference(f, iq, ref.data());
    ASSERT_TRUE(dev.value()->eval_interp(iq, got.data()).ok());
    EXPECT_LE(rel_diff(got, ref), k_tol) << "interpolated, padded chroma, block_C " << (told ? "given" : "empty");
  }
}

TEST(OpenCL, DecodeKernelsMatchReference) {
  REQUIRE_CL();
  for (int mode : {BTFC_FMF_RGB, BTFC_FMF_DFMF})
    for (int C : {3, 17}) {
      fmf_cl::PackedFactors f = random_factors(mode, C, 11, 3, 19 * 7, unsigned(100 + C + mode));
      if (mode == BTFC_FMF_DFMF)
        for (float& x : f.SxV) x *= 0.3f;
      auto dev = fmf_cl::DeviceFactors::upload(f);
      ASSERT_TRUE(dev.ok());
      // A region of texels and a direction subset whose row count is not a multiple of 16.
      std::vector<int> texels = {0, 5, 6, 7, 100, 132}, lights = {10, 0, 3, 4, 5, 6, 7}, views = {2, 0};
      const size_t rows = 3 * lights.size() * views.size();
      std::vector<float> ref(texels.size() * rows), got(ref.size());
      fmf_cl::decode_reference(f, texels, lights, views, ref.data());
      ASSERT_TRUE(dev.value()->decode(texels, lights, views, got.data()).ok());
      EXPECT_LE(rel_diff(got, ref), k_tol) << "mode " << mode << " C " << C;
    }
  // dfmf with chroma blocks of fewer components than the luminance's (zero-padded to C; the
  // kernel stops at each block's own count, block_C), over every light: 33 directions, so whole
  // 16-direction strips of 4 texels and the tails.
  for (bool told : {true, false}) {
    const int C = 17, own[3] = {C, 5, 2};
    const fmf_cl::PackedFactors f = padded_chroma(C, own, told, 321);
    auto dev = fmf_cl::DeviceFactors::upload(f);
    ASSERT_TRUE(dev.ok());
    std::vector<int> texels = {0, 5, 6, 7, 100, 132, 3, 4, 9}, lights, views = {2, 0, 1};
    for (int l = 0; l < 11; ++l) lights.push_back((l * 7) % 11);
    const size_t rows = 3 * lights.size() * views.size();
    std::vector<float> ref(texels.size() * rows), got(ref.size());
    fmf_cl::decode_reference(f, texels, lights, views, ref.data());
    ASSERT_TRUE(dev.value()->decode(texels, lights, views, got.data()).ok());
    EXPECT_LE(rel_diff(got, ref), k_tol) << "padded chroma, block_C " << (told ? "given" : "empty");
  }
}

TEST(OpenCL, ModelDecodeAndEvalOnSyntheticBtfMatchCpuPath) {
  REQUIRE_CL();
  SynthOptions so;
  so.width = 21, so.height = 13;  // odd, texel count not a multiple of anything
  so.views.dirs.resize(7);
  so.views.name = "custom";
  auto btf = synthesize_btf(so);
  ASSERT_TRUE(btf.ok());
  for (const char* spec : {"fmf:rank=12", "fmf:rank=12:color=dfmf:chroma_rank=5"}) {
    auto r = resolve_spec(spec);
    Context ctx;
    auto m = r->first->encode(btf.value(), r->second, ctx);
    ASSERT_TRUE(m.ok());
    Btf cpu, cl;
    ocl::set_device_choice(ocl::DeviceChoice::cpu);
    ASSERT_TRUE(m.value()->decode_all(cpu).ok());
    std::vector<EvalQuery> q;
    std::mt19937 rng(3);
    for (int i = 0; i < 500; ++i) {
      EvalQuery e;
      e.x = int(rng() % 21), e.y = int(rng() % 13);
      if (i % 2) e.light = int(rng() % 81), e.view = int(rng() % 7);
      else e.wl = dir_from_theta_phi(1.3 * (rng() % 1000) / 1000.0, 6.28 * (rng() % 1000) / 1000.0),
           e.wv = dir_from_theta_phi(0.5 * (rng() % 1000) / 1000.0, 6.28 * (rng() % 1000) / 1000.0);
      q.push_back(e);
    }
    std::vector<float> ecpu(3 * q.size()), ecl(3 * q.size());
    ASSERT_TRUE(m.value()->eval_batch(q, ecpu.data()).ok());
    ocl::set_device_choice(ocl::DeviceChoice::cl);
    ASSERT_TRUE(m.value()->decode_all(cl).ok());
    ASSERT_TRUE(m.value()->eval_batch(q, ecl.data()).ok());
    ocl::set_device_choice(ocl::DeviceChoice::automatic);
    std::vector<float> a(cpu.data(), cpu.data() + cpu.size()), b(cl.data(), cl.data() + cl.size());
    EXPECT_LE(rel_diff(b, a), k_tol) << spec;
    EXPECT_LE(rel_diff(ecl, ecpu), k_tol) << spec;
  }
}

// The runtime caches programs by source folder (BTFC_KERNEL_DIR), so this holds in one process
// after other OpenCL tests too, and leaves no broken program behind for the tests after it.
TEST(OpenCL, BrokenKernelGivesCompilerLogAndAutoFallsBack) {
  REQUIRE_CL();
  const std::string dir = ::testing::TempDir() + "btfc_broken_kernels_" + std::to_string(::getpid());
  std::filesystem::create_directories(dir);
  std::filesystem::copy_file(std::string(BTFC_SOURCE_DIR) + "/kernels/btfc_shared.h", dir + "/btfc_shared.h",
                             std::filesystem::copy_options::overwrite_existing);
  std::ofstream(dir + "/fmf.cl") << "__kernel void fmf_eval_measured(__global float* x) { this is not C; }\n";
  setenv("BTFC_KERNEL_DIR", dir.c_str(), 1);
  fmf_cl::PackedFactors f = random_factors(BTFC_FMF_RGB, 4, 3, 2, 10, 1);
  auto dev = fmf_cl::DeviceFactors::upload(f);
  ASSERT_TRUE(dev.ok());
  std::vector<fmf_cl::MeasuredQuery> q = {{1, 2, 1, 0}};
  float out[3];
  Status s = dev.value()->eval_measured(q, out);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.code(), StatusCode::device_error);
  EXPECT_NE(s.message().find("building OpenCL program fmf.cl failed"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("compiler log"), std::string::npos);
  EXPECT_NE(s.message().find("error"), std::string::npos) << "the log names the compile error: " << s.message();
  // Through a model: --device cl reports the error, --device auto warns and runs the CPU path.
  Btf b = Btf::create([] {
            BtfDesc d;
            d.width = 3, d.height = 2;
            d.lights = DirectionSet::ubo2003();
            d.views = DirectionSet::single(Vec3{0, 0, 1});
            return d;
          }())
              .value();
  for (size_t i = 0; i < b.size(); ++i) b.data()[i] = float(i % 7) * 0.1f;
  auto r = resolve_spec("fmf:rank=2");
  Context ctx;
  auto m = r->first->encode(b, r->second, ctx);
  Btf out_b;
  ocl::set_device_choice(ocl::DeviceChoice::cl);
  EXPECT_EQ(m.value()->decode_all(out_b).code(), StatusCode::device_error);
  ocl::set_device_choice(ocl::DeviceChoice::automatic);
  testing::internal::CaptureStderr();
  ASSERT_TRUE(m.value()->decode_all(out_b).ok());
  const std::string err = testing::internal::GetCapturedStderr();
  EXPECT_NE(err.find("warning: OpenCL failed, running the CPU path"), std::string::npos) << err;
  EXPECT_NE(ocl::fallback_reason().find("fmf.cl"), std::string::npos);
  unsetenv("BTFC_KERNEL_DIR");
  std::filesystem::remove_all(dir);
}

TEST(OpenCL, DeviceChoiceParsing) {
  EXPECT_EQ(ocl::parse_device_choice("cpu").value(), ocl::DeviceChoice::cpu);
  EXPECT_EQ(ocl::parse_device_choice("cl").value(), ocl::DeviceChoice::cl);
  EXPECT_EQ(ocl::parse_device_choice("auto").value(), ocl::DeviceChoice::automatic);
  EXPECT_FALSE(ocl::parse_device_choice("gpu").ok());
}

// `cpu` never loads the OpenCL library (core/cl_runtime.h), though codecs with kernels run.
// Runs in its own process under ctest (gtest_discover_tests), where nothing loaded it before.
TEST(OpenCL, CpuChoiceNeverLoadsTheLibrary) {
  if (ocl::library_loaded()) GTEST_SKIP() << "an earlier test of this process loaded OpenCL (run it alone, as ctest does)";
  ocl::set_device_choice(ocl::DeviceChoice::cpu);
  SynthOptions so;
  so.width = 7, so.height = 5;
  auto btf = synthesize_btf(so);
  ASSERT_TRUE(btf.ok());
  for (const char* spec : {"fmf:rank=3", "lpyr", "lpca:clusters=2:components=2"}) {
    auto r = resolve_spec(spec);
    Context ctx;
    auto m = r->first->encode(btf.value(), r->second, ctx);
    ASSERT_TRUE(m.ok()) << spec;
    Btf out;
    ASSERT_TRUE(m.value()->decode_all(out).ok()) << spec;
  }
  EXPECT_FALSE(ocl::Runtime::get().ok());
  EXPECT_FALSE(ocl::list_devices().ok());
  EXPECT_NE(ocl::device_summary().find("CPU path chosen"), std::string::npos);
  EXPECT_FALSE(ocl::library_loaded());
  ocl::set_device_choice(ocl::DeviceChoice::automatic);
}
