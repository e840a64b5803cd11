// OpenCL kernels of the second round against their C++ references: fmf's direction-pair and
// grouped batch evaluation, lpca's assignment step and relighting, lpyr's pyramid operators.
// Random and synthetic-BTF inputs, odd sizes, sizes that are not multiples of the work-group
// size or of the kernels' blocking. Under BTFC_FORCE_CPU=1 (the suite's second pass) or without
// an OpenCL device the kernel comparisons are skipped and say so; the codec-level tests then
// exercise the CPU path only.
#include <gtest/gtest.h>

#include <Eigen/QR>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>

#include "tests/require_cl.h"
#include "codecs/codec.h"
#include "codecs/fmf/fmf_cl.h"
#include "codecs/lpca/clustering.h"
#include "codecs/lpca/lpca.h"
#include "codecs/lpca/lpca_cl.h"
#include "codecs/lpyr/lpyr_cl.h"
#include "codecs/lpyr/lpyr_internal.h"
#include "core/cl_runtime.h"
#include "core/synth.h"
#include "tests/cl_test_util.h"
#include "tests/test_paths.h"

using namespace btfc;

namespace {

using test::random_factors;
using test::rel_diff;

btfc_fmf_query random_pair(std::mt19937& rng, int nL, int nV, bool exact) {
  btfc_fmf_query q{};
  float sl = 0, sv = 0;
  for (int j = 0; j < 3; ++j) {
    q.light[j] = int(rng() % nL), q.view[j] = int(rng() % nV);
    q.wl[j] = exact && j ? 0.f : float(rng() % 1000 + 1) / 1000.f;
    q.wv[j] = exact && j ? 0.f : float(rng() % 1000 + 1) / 1000.f;
    sl += q.wl[j], sv += q.wv[j];
  }
  for (int j = 0; j < 3; ++j) q.wl[j] /= sl, q.wv[j] /= sv;
  return q;
}

constexpr double k_tol = 1e-5;  // float rounding of C-term sums (and fast-relaxed-math exp)

}  // namespace

// ---- fmf ---------------------------------------------------------------------------------------

TEST(OpenCLKernels, FmfPairBlendEqualsNineLookups) {
  // The blended-rows path is algebraically the 9-lookup interpolation: checks the reference
  // itself (runs on the CPU pass too).
  for (int C : {1, 7, 32, 33}) {
    fmf_cl::PackedFactors f = random_factors(BTFC_FMF_RGB, C, 13, 5, 37 * 11, unsigned(C));
    std::mt19937 rng(7);
    const btfc_fmf_query pair = random_pair(rng, 13, 5, false);
    std::vector<int> texels(1001);
    for (int& t : texels) t = int(rng() % f.texels);
    std::vector<btfc_fmf_query> q(texels.size(), pair);
    for (size_t i = 0; i < q.size(); ++i) q[i].texel = texels[i];
    std::vector<float> a(3 * q.size()), b(a.size());
    fmf_cl::eval_pair_reference(f, pair, texels, a.data());
    fmf_cl::eval_interp_reference(f, q, b.data());
    EXPECT_LE(rel_diff(a, b), k_tol) << "C " << C;
    EXPECT_GT(rel_diff(a, std::vector<float>(a.size(), 0.f)), 0.1) << "non-trivial values";
  }
}

TEST(OpenCLKernels, FmfPairAndBatchKernelsMatchReference) {
  REQUIRE_CL();
  // mode 2: dfmf with a luminance offset other than Bonn's (a kernel argument, as the model's).
  for (int mode : {BTFC_FMF_RGB, BTFC_FMF_DFMF, 2})
    for (int C : {1, 7, 32, 37}) {
      const int nL = 13, nV = 5, texels = 37 * 11;
      fmf_cl::PackedFactors f = random_factors(std::min(mode, int(BTFC_FMF_DFMF)), C, nL, nV, texels, unsigned(C + 100 * mode));
      if (mode == 2) f.eps = 0.37f;
      auto dev = fmf_cl::DeviceFactors::upload(f);
      ASSERT_TRUE(dev.ok()) << dev.status().message();
      std::mt19937 rng(11);
      // One pair, a texel list whose length is not a multiple of the work-group size.
      std::vector<int> tex(1001);
      for (int& t : tex) t = int(rng() % texels);
      for (bool exact : {false, true}) {
        const btfc_fmf_query pair = random_pair(rng, nL, nV, exact);
        std::vector<float> ref(3 * tex.size()), got(ref.size());
        fmf_cl::eval_pair_reference(f, pair, tex, ref.data());
        ASSERT_TRUE(dev.value()->eval_pair(pair, tex, got.data()).ok());
        EXPECT_LE(rel_diff(got, ref), k_tol) << "pair, mode " << mode << " C " << C << " exact " << exact;
      }
      // A mixed batch: long runs of one pair (frames), short runs (below k_min_pair_run), random queries.
      std::vector<btfc_fmf_query> q;
      for (size_t run : {size_t(200), size_t(3), fmf_cl::k_min_pair_run - 1, size_t(1), fmf_cl::k_min_pair_run, size_t(517)}) {
        const btfc_fmf_query p = random_pair(rng, nL, nV, false);
        for (size_t i = 0; i < run; ++i) q.push_back(p), q.back().texel = int(rng() % texels);
      }
      std::vector<float> ref(3 * q.size()), got(ref.size()), nine(ref.size());
      fmf_cl::eval_batch_reference(f, q, ref.data());
      fmf_cl::eval_interp_reference(f, q, nine.data());
      ASSERT_TRUE(dev.value()->eval_batch(q, got.data()).ok());
      EXPECT_LE(rel_diff(got, ref), k_tol) << "batch, mode " << mode << " C " << C;
      EXPECT_LE(rel_diff(ref, nine), k_tol) << "batch = 9 lookups, mode " << mode << " C " << C;
    }
}

namespace {

// An fmf model of a synthetic BTF (UBO2003 lights, the first `views` views), for the
// model-level comparisons below; null (and a test failure) if it cannot be made.
std::unique_ptr<Model> synthetic_fmf(int width, int height, size_t views, float scale, const std::string& spec) {
  SynthOptions so;
  so.width = width, so.height = height, so.scale = scale;
  so.views.dirs.resize(views);
  so.views.name = "custom";
  auto btf = synthesize_btf(so);
  EXPECT_TRUE(btf.ok());
  auto r = resolve_spec(spec);
  EXPECT_TRUE(r.ok());
  if (!btf.ok() || !r.ok()) return nullptr;
  Context ctx;
  auto m = r->first->encode(btf.value(), r->second, ctx);
  EXPECT_TRUE(m.ok()) << m.status().message();
  return m.ok() ? std::move(m).value() : nullptr;
}

// eval_batch on the CPU path and on OpenCL, the same queries: equal to k_tol.
void expect_cl_eval_equals_cpu(const Model& m, const std::vector<EvalQuery>& q) {
  std::vector<float> cpu(3 * q.size()), cl(cpu.size());
  ocl::set_device_choice(ocl::DeviceChoice::cpu);
  ASSERT_TRUE(m.eval_batch(q, cpu.data()).ok());
  ocl::set_device_choice(ocl::DeviceChoice::cl);
  ASSERT_TRUE(m.eval_batch(q, cl.data()).ok());
  ocl::set_device_choice(ocl::DeviceChoice::automatic);
  EXPECT_LE(rel_diff(cl, cpu), k_tol);
}

}  // namespace

TEST(OpenCLKernels, FmfModelCoherentBatchMatchesCpuPath) {
  REQUIRE_CL();
  auto m = synthetic_fmf(21, 13, 7, 1, "fmf:rank=12");
  ASSERT_TRUE(m);
  // Two frames of every texel under one (wl, wv) each, then a few scattered queries.
  std::vector<EvalQuery> q;
  std::mt19937 rng(3);
  for (int frame = 0; frame < 2; ++frame) {
    const Vec3 wl = dir_from_theta_phi(0.3 + frame, 1.0 + frame), wv = dir_from_theta_phi(0.2 * frame, 2.0);
    for (int y = 0; y < 13; ++y)
      for (int x = 0; x < 21; ++x) {
        EvalQuery e;
        e.x = x, e.y = y, e.wl = wl, e.wv = wv;
        q.push_back(e);
      }
  }
  for (int i = 0; i < 50; ++i) {
    EvalQuery e;
    e.x = int(rng() % 21), e.y = int(rng() % 13), e.light = int(rng() % 81), e.view = int(rng() % 7);
    q.push_back(e);
  }
  expect_cl_eval_equals_cpu(*m, q);
}

TEST(OpenCLKernels, FmfDfmfModelWithItsOwnOffsetMatchesCpuPath) {
  // color=dfmf's default offset comes from the data (not Bonn's 1e-5): the kernels take it as an
  // argument, so such a model's decode and eval_batch run on OpenCL and equal the CPU path.
  REQUIRE_CL();
  auto m = synthetic_fmf(19, 11, 9, 30, "fmf:color=dfmf:rank=10:chroma_rank=4:precision=float");
  ASSERT_TRUE(m);
  ASSERT_EQ(m->spec().find("offset=1e-05"), std::string::npos) << m->spec();
  std::vector<EvalQuery> q;
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(0, 1);
  for (int i = 0; i < 3000; ++i) {
    EvalQuery e;
    e.x = int(rng() % 19), e.y = int(rng() % 11);
    if (i % 5 == 0) e.light = int(rng() % 81), e.view = int(rng() % 9);
    else e.wl = dir_from_theta_phi(u(rng) * 1.4, u(rng) * 6.28), e.wv = dir_from_theta_phi(u(rng) * 1.4, u(rng) * 6.28);
    q.push_back(e);
  }
  expect_cl_eval_equals_cpu(*m, q);
  Btf dcpu, dcl;
  ocl::set_device_choice(ocl::DeviceChoice::cpu);
  ASSERT_TRUE(m->decode(DecodeRequest{}, dcpu).ok());
  ocl::set_device_choice(ocl::DeviceChoice::cl);
  ASSERT_TRUE(m->decode(DecodeRequest{}, dcl).ok());
  ocl::set_device_choice(ocl::DeviceChoice::automatic);
  EXPECT_LE(rel_diff(std::vector<float>(dcl.data(), dcl.data() + dcl.size()), std::vector<float>(dcpu.data(), dcpu.data() + dcpu.size())), k_tol);
}

// ---- lpca --------------------------------------------------------------------------------------

namespace {

struct ProjectCase {
  std::vector<float> X, W;
  lpca_cl::ProjectionTable table;
  lpca_cl::GroupBatch batch;
  int d = 0, c = 0;
};

// Random texels and vectors; `groups` groups of 8 random texels (repeats included, as in short
// groups), each with a random ascending set of 1..K candidate clusters.
ProjectCase make_project_case(int d, int nt, int K, int c, int groups, unsigned seed) {
  ProjectCase pc;
  pc.d = d, pc.c = c;
  std::mt19937 rng(seed);
  std::normal_distribution<float> g(0, 1);
  pc.X.resize(size_t(d) * nt);
  for (float& x : pc.X) x = 1.0f + g(rng);  // an offset, as ABRDFs have: sums of one sign
  pc.W.resize(size_t(d) * K * (c + 1));
  for (float& w : pc.W) w = g(rng);
  lpca_cl::fill_projection_table(pc.W.data(), d, K, c, pc.table);
  pc.batch.X = pc.X.data(), pc.batch.nt = nt;
  pc.batch.cand_off.push_back(0);
  for (int gi = 0; gi < groups; ++gi) {
    for (int i = 0; i < 8; ++i) pc.batch.texels.push_back(uint32_t(rng() % nt));
    const size_t before = pc.batch.cand.size();
    const int want = 1 + int(rng() % K);
    for (int k = 0; k < K; ++k)
      if (int(rng() % K) < want) pc.batch.cand.push_back(uint32_t(k));
    if (pc.batch.cand.size() == before) pc.batch.cand.push_back(uint32_t(rng() % K));
    pc.batch.cand_off.push_back(uint32_t(pc.batch.cand.size()));
  }
  return pc;
}

}  // namespace

TEST(OpenCLKernels, LpcaProjectKernelMatchesReference) {
  REQUIRE_CL();
  // d not a multiple of 16 or of the 1024-direction chunk (2500: three chunks); c + 1 below, at
  // and above one strip of 16 (S = 2); one group and many.
  struct S {
    int d, nt, K, c, groups;
  };
  for (S s : {S{37, 100, 5, 3, 13}, S{2500, 60, 7, 2, 9}, S{1030, 40, 3, 15, 5}, S{19, 9, 4, 20, 7}, S{1, 3, 2, 1, 1}}) {
    ProjectCase pc = make_project_case(s.d, s.nt, s.K, s.c, s.groups, unsigned(s.d + s.nt));
    const size_t stride = size_t(pc.table.V), n = pc.batch.cand.size() * 8 * stride;
    std::vector<float> ref(n, -1.f), got(n, -2.f);
    lpca_cl::project_reference(pc.table, pc.batch, ref.data());
    ASSERT_TRUE(lpca_cl::project_cl(pc.table, pc.batch, got.data()).ok()) << "d " << s.d;
    // The reference against plain dot products in double, relative to ||x|| ||w||; the kernel
    // against the reference on every used entry (padding lanes are zero in both).
    double worst_ref = 0, worst_cl = 0;
    for (size_t g = 0; g < pc.batch.groups(); ++g)
      for (uint32_t p = pc.batch.cand_off[g]; p < pc.batch.cand_off[g + 1]; ++p)
        for (int i = 0; i < 8; ++i)
          for (int j = 0; j <= s.c; ++j) {
            const float* x = pc.X.data() + size_t(pc.batch.texels[g * 8 + size_t(i)]) * s.d;
            const float* w = pc.W.data() + (size_t(pc.batch.cand[p]) * (s.c + 1) + j) * s.d;
            double dot = 0, xx = 0, ww = 0;
            for (int r = 0; r < s.d; ++r) dot += double(x[r]) * w[r], xx += double(x[r]) * x[r], ww += double(w[r]) * w[r];
            const size_t at = (size_t(p) * 8 + size_t(i)) * stride + size_t(j);
            const double scale = std::sqrt(xx * ww) + 1e-30;
            worst_ref = std::max(worst_ref, std::fabs(ref[at] - dot) / scale);
            worst_cl = std::max(worst_cl, std::fabs(double(got[at]) - ref[at]) / scale);
          }
    EXPECT_LE(worst_ref, 1e-5) << "d " << s.d << " c " << s.c;
    EXPECT_LE(worst_cl, 1e-5) << "d " << s.d << " c " << s.c;
  }
}

TEST(OpenCLKernels, LpcaFitOnSyntheticBtfMatchesCpuPath) {
  REQUIRE_CL();
  SynthOptions so;
  so.width = 19, so.height = 11;  // 209 texels: not a multiple of 8
  so.views.dirs.resize(5);
  so.views.name = "custom";
  auto btf = synthesize_btf(so);
  ASSERT_TRUE(btf.ok());
  lpca::FitOptions opt;
  opt.clusters = 6, opt.components = 3, opt.iters = 6, opt.seed = 2;
  ocl::set_device_choice(ocl::DeviceChoice::cpu);
  auto cpu = lpca::fit_local_pca(btf.value(), opt);
  ocl::set_device_choice(ocl::DeviceChoice::cl);
  auto cl = lpca::fit_local_pca(btf.value(), opt);
  ocl::set_device_choice(ocl::DeviceChoice::automatic);
  ASSERT_TRUE(cpu.ok() && cl.ok());
  ASSERT_EQ(cpu->sq_error.size(), cl->sq_error.size());
  for (size_t i = 0; i < cpu->sq_error.size(); ++i)
    EXPECT_NEAR(cl->sq_error[i], cpu->sq_error[i], 1e-4 * cpu->sq_error[i]) << "iteration " << i;
  EXPECT_EQ(cl->cluster_of, cpu->cluster_of);
}

TEST(OpenCLKernels, LpcaRelightKernelMatchesReference) {
  REQUIRE_CL();
  for (int c : {1, 8, 13}) {
    const int K = 7;
    const size_t n = 1001, rows = size_t(K) * (c + 1);
    std::mt19937 rng(static_cast<unsigned>(c));
    std::uniform_real_distribution<float> u(-1, 1);
    std::vector<uint32_t> cl_of(n);
    std::vector<float> W(n * size_t(c)), L(rows * 3);
    for (auto& v : cl_of) v = uint32_t(rng() % K);
    for (float& x : W) x = u(rng);
    for (float& x : L) x = u(rng) * 1e3f;  // HDR lighting scale
    std::vector<float> ref(3 * n), got(ref.size());
    lpca_cl::relight_reference(cl_of, W.data(), c, L.data(), ref.data());
    ASSERT_TRUE(lpca_cl::relight_cl(cl_of, W.data(), c, L.data(), rows, got.data()).ok());
    EXPECT_LE(rel_diff(got, ref), k_tol) << "c " << c;
  }
}

TEST(OpenCLKernels, LpcaModelRelightMatchesCpuPath) {
  REQUIRE_CL();
  SynthOptions so;
  so.width = 13, so.height = 9;
  so.views.dirs.resize(7);
  so.views.name = "custom";
  auto btf = synthesize_btf(so);
  ASSERT_TRUE(btf.ok());
  auto r = resolve_spec("lpca:clusters=4:components=3");
  ASSERT_TRUE(r.ok()) << r.status().message();
  Context ctx;
  ocl::set_device_choice(ocl::DeviceChoice::cpu);
  auto m = r->first->encode(btf.value(), r->second, ctx);
  ASSERT_TRUE(m.ok()) << m.status().message();
  EnvironmentSH env;
  env.order = 3;
  std::mt19937 rng(9);
  for (int i = 0; i < 27; ++i) env.coeffs.push_back(std::uniform_real_distribution<double>(0, 2)(rng));
  int w = 0, h = 0;
  auto a = relight(*m.value(), env, dir_from_theta_phi(0.4, 1.0), w, h);
  ocl::set_device_choice(ocl::DeviceChoice::cl);
  auto b = relight(*m.value(), env, dir_from_theta_phi(0.4, 1.0), w, h);
  ocl::set_device_choice(ocl::DeviceChoice::automatic);
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ(w, 13);
  EXPECT_LE(rel_diff(b.value(), a.value()), k_tol);
}

// ---- lpyr --------------------------------------------------------------------------------------

TEST(OpenCLKernels, LpyrPyramidKernelsMatchReference) {
  REQUIRE_CL();
  struct S {
    int w, h;
    size_t d;
  };
  // Odd sizes, one texel, one row / column, d not a multiple of 16 or of the 64-value run.
  for (S s : {S{13, 7, 17}, S{1, 1, 3}, S{2, 5, 100}, S{1, 9, 1}, S{16, 3, 64}, S{9, 1, 129}}) {
    std::mt19937 rng(unsigned(s.w * 100 + s.h));
    std::uniform_real_distribution<float> u(0, 1);
    std::vector<float> f(size_t(s.w) * s.h * s.d);
    for (float& x : f) x = u(rng) * 1e4f;
    const size_t n2 = size_t((s.w + 1) / 2) * ((s.h + 1) / 2) * s.d;
    std::vector<float> nr(n2), nc(n2);
    lpyr::reduce(f.data(), s.w, s.h, s.d, nr.data());
    ASSERT_TRUE(lpyr::reduce_cl(f.data(), s.w, s.h, s.d, nc.data()).ok());
    EXPECT_LE(rel_diff(nc, nr), 1e-6) << s.w << "x" << s.h << " d " << s.d;
    std::vector<float> fr = f, fc = f;
    lpyr::subtract_up(fr.data(), s.w, s.h, s.d, nr.data());
    ASSERT_TRUE(lpyr::subtract_up_cl(fc.data(), s.w, s.h, s.d, nr.data()).ok());
    EXPECT_LE(rel_diff(fc, fr), 1e-6) << s.w << "x" << s.h << " d " << s.d;
  }
}

TEST(OpenCLKernels, LpyrEncodeMatchesCpuPath) {
  REQUIRE_CL();
  SynthOptions so;
  so.width = 15, so.height = 9;
  so.views.dirs.resize(3);
  so.views.name = "custom";
  auto btf = synthesize_btf(so);
  ASSERT_TRUE(btf.ok());
  auto r = resolve_spec("lpyr:precision=float");
  ASSERT_TRUE(r.ok()) << r.status().message();
  Btf out[2];
  for (int i = 0; i < 2; ++i) {
    ocl::set_device_choice(i ? ocl::DeviceChoice::cl : ocl::DeviceChoice::cpu);
    Context ctx;
    auto m = r->first->encode(btf.value(), r->second, ctx);
    ASSERT_TRUE(m.ok()) << m.status().message();
    ASSERT_TRUE(m.value()->decode_all(out[i]).ok());
  }
  ocl::set_device_choice(ocl::DeviceChoice::automatic);
  EXPECT_LE(rel_diff(out[1].data(), out[0].data(), out[0].size()), 1e-4);
}

// A broken lpca.cl / lpyr.cl (development override) gives the compiler log under --device cl and
// falls back to the C++ references with a warning under --device auto. Programs are cached by
// source folder (BTFC_KERNEL_DIR), so this holds in one process after other OpenCL tests too.
TEST(OpenCLKernels, BrokenLpcaAndLpyrKernelsFallBack) {
  REQUIRE_CL();
  const std::string dir = ::testing::TempDir() + "btfc_broken_codec_kernels_" + std::to_string(::getpid());
  std::filesystem::create_directories(dir);
  std::filesystem::copy_file(std::string(BTFC_SOURCE_DIR) + "/kernels/btfc_shared.h", dir + "/btfc_shared.h",
                             std::filesystem::copy_options::overwrite_existing);
  std::ofstream(dir + "/lpca.cl") << "__kernel void lpca_project(__global float* x) { not C either }\n";
  std::ofstream(dir + "/lpyr.cl") << "__kernel void lpyr_reduce(__global float* x) { still not C }\n";
  setenv("BTFC_KERNEL_DIR", dir.c_str(), 1);
  ProjectCase pc = make_project_case(19, 40, 3, 2, 5, 1);
  const size_t n = pc.batch.cand.size() * 8 * size_t(pc.table.V);
  std::vector<float> ps(n), pr(n);
  Status bad = lpca_cl::project_cl(pc.table, pc.batch, ps.data());
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.code(), StatusCode::device_error);
  EXPECT_NE(bad.message().find("building OpenCL program lpca.cl failed"), std::string::npos) << bad.message();
  EXPECT_NE(bad.message().find("compiler log"), std::string::npos);
  std::vector<float> src(5 * 3 * 4, 1.f), dst(3 * 2 * 4);
  Status ls = lpyr::reduce_cl(src.data(), 5, 3, 4, dst.data());
  EXPECT_EQ(ls.code(), StatusCode::device_error);
  EXPECT_NE(ls.message().find("lpyr.cl"), std::string::npos) << ls.message();
  // --device cl: the dispatchers report the error; auto: they warn once and run the reference.
  ocl::set_device_choice(ocl::DeviceChoice::cl);
  EXPECT_FALSE(lpca_cl::project(pc.table, pc.batch, ps.data()).ok());
  EXPECT_FALSE(lpyr::reduce_any(src.data(), 5, 3, 4, dst.data()).ok());
  ocl::set_device_choice(ocl::DeviceChoice::automatic);
  ASSERT_TRUE(lpca_cl::project(pc.table, pc.batch, ps.data()).ok());
  lpca_cl::project_reference(pc.table, pc.batch, pr.data());
  EXPECT_EQ(ps, pr);
  std::fill(dst.begin(), dst.end(), 0.f);
  ASSERT_TRUE(lpyr::reduce_any(src.data(), 5, 3, 4, dst.data()).ok());
  for (float v : dst) EXPECT_FLOAT_EQ(v, 1.f);  // box mean of a constant
  EXPECT_NE(ocl::fallback_reason().find(".cl"), std::string::npos) << ocl::fallback_reason();
  unsetenv("BTFC_KERNEL_DIR");
  std::filesystem::remove_all(dir);
}
