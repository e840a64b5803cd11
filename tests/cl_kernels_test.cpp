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

using namespace btfc;

namespace {


// max |a - b| / max(1e-30, max |b|): relative to the data's scale.
double rel_diff(const float* a, const float* b, size_t n) {
  double d = 0, m = 1e-30;
  for (size_t i = 0; i < n; ++i) d = std::max(d, double(std::fabs(a[i] - b[i]))), m = std::max(m, double(std::fabs(b[i])));
  return d / m;
}
double rel_diff(const std::vector<float>& a, const std::vector<float>& b) { return rel_diff(a.data(), b.data(), b.size()); }

fmf_cl::PackedFactors random_factors(int mode, int C, int nL, int nV, int texels, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-1, 1);
  fmf_cl::PackedFactors f;
  f.mode = mode, f.C = C, f.nL = nL, f.nV = nV, f.texels = texels;
  f.blocks = mode == BTFC_FMF_RGB ? 1 : 3;
  f.rows_per_block = mode == BTFC_FMF_RGB ? 3 * nL * nV : nL * nV;
  f.U.resize(size_t(f.blocks) * f.rows_per_block * C);
  f.SxV.resize(size_t(f.blocks) * texels * C);
  for (float& x : f.U) x = u(rng) / std::sqrt(float(C));
  for (float& x : f.SxV) x = u(rng) * (mode == BTFC_FMF_RGB ? 1.0f : 0.3f);
  return f;
}

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
  for (int mode : {BTFC_FMF_RGB, BTFC_FMF_DFMF})
    for (int C : {1, 7, 32, 37}) {
      const int nL = 13, nV = 5, texels = 37 * 11;
      fmf_cl::PackedFactors f = random_factors(mode, C, nL, nV, texels, unsigned(C + 100 * mode));
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

TEST(OpenCLKernels, FmfModelCoherentBatchMatchesCpuPath) {
  REQUIRE_CL();
  SynthOptions so;
  so.width = 21, so.height = 13;
  so.views.dirs.resize(7);
  so.views.name = "custom";
  auto btf = synthesize_btf(so);
  ASSERT_TRUE(btf.ok());
  auto r = resolve_spec("fmf:rank=12");
  Context ctx;
  auto m = r->first->encode(btf.value(), r->second, ctx);
  ASSERT_TRUE(m.ok());
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
  std::vector<float> cpu(3 * q.size()), cl(cpu.size());
  ocl::set_device_choice(ocl::DeviceChoice::cpu);
  ASSERT_TRUE(m.value()->eval_batch(q, cpu.data()).ok());
  ocl::set_device_choice(ocl::DeviceChoice::cl);
  ASSERT_TRUE(m.value()->eval_batch(q, cl.data()).ok());
  ocl::set_device_choice(ocl::DeviceChoice::automatic);
  EXPECT_LE(rel_diff(cl, cpu), k_tol);
}

// ---- lpca --------------------------------------------------------------------------------------

namespace {

struct AssignCase {
  std::vector<float> X, W;
  std::vector<double> x2;
  lpca_cl::AssignProblem p;
};

// Clusters around K random centres with orthonormal bases; cluster 1 has no basis (skipped).
AssignCase make_assign_case(int d, int N, int K, int c, unsigned seed) {
  AssignCase a;
  std::mt19937 rng(seed);
  std::normal_distribution<float> g(0, 1);
  const int M = K * (c + 1);
  a.W.assign(size_t(d) * M, 0.f);
  a.p.mu2.assign(size_t(K), -1.0);
  a.p.muE.assign(size_t(K) * c, 0.0);
  for (int k = 0; k < K; ++k) {
    Eigen::MatrixXf B(d, c + 1);
    for (int i = 0; i < B.size(); ++i) B.data()[i] = g(rng);
    Eigen::HouseholderQR<Eigen::MatrixXf> qr(B.rightCols(c));
    Eigen::MatrixXf E = qr.householderQ() * Eigen::MatrixXf::Identity(d, c);
    Eigen::Map<Eigen::MatrixXf> Wk(a.W.data() + size_t(k) * (c + 1) * d, d, c + 1);
    if (k == 1) continue;
    Wk.col(0) = B.col(0);
    Wk.rightCols(c) = E;
    a.p.mu2[size_t(k)] = B.col(0).cast<double>().squaredNorm();
    for (int j = 0; j < c; ++j) a.p.muE[size_t(k) * c + j] = E.col(j).cast<double>().dot(B.col(0).cast<double>());
  }
  a.X.resize(size_t(d) * N);
  a.x2.resize(size_t(N));
  for (int t = 0; t < N; ++t) {
    const int k = int(rng() % K);
    for (int r = 0; r < d; ++r) a.X[size_t(t) * d + r] = a.W[size_t(k) * (c + 1) * d + r] + 0.5f * g(rng);
    a.x2[size_t(t)] = Eigen::Map<const Eigen::VectorXf>(a.X.data() + size_t(t) * d, d).cast<double>().squaredNorm();
  }
  a.p.X = a.X.data(), a.p.d = d, a.p.N = N, a.p.K = K, a.p.c = c, a.p.W = a.W.data(), a.p.x2 = a.x2.data();
  return a;
}

}  // namespace

TEST(OpenCLKernels, LpcaAssignKernelMatchesReference) {
  REQUIRE_CL();
  // d not a multiple of 16 or of the kernel's 1024-direction chunk; N not a multiple of 8;
  // K (c + 1) not a multiple of 16; c = 0 would be rejected by the codec, so c >= 1.
  struct S {
    int d, N, K, c;
  };
  for (S s : {S{37, 1003, 5, 3}, S{2500, 333, 7, 2}, S{19, 7, 2, 1}, S{1, 9, 3, 1}}) {
    AssignCase a = make_assign_case(s.d, s.N, s.K, s.c, unsigned(s.d + s.N));
    std::vector<uint32_t> init(size_t(s.N));
    std::mt19937 rng(5);
    for (auto& v : init) v = uint32_t(rng() % s.K);
    std::vector<uint32_t> ra = init, ca = init;
    std::vector<double> re(size_t(s.N)), ce(size_t(s.N));
    const int rm = lpca_cl::assign_reference(a.p, ra.data(), re.data());
    auto cm = lpca_cl::assign_cl(a.p, ca.data(), ce.data());
    ASSERT_TRUE(cm.ok()) << cm.status().message();
    EXPECT_EQ(cm.value(), rm) << "d " << s.d;
    EXPECT_GT(rm, 0) << "the case moves texels";
    int differ = 0;
    double worst = 0;
    for (int t = 0; t < s.N; ++t) {
      differ += ra[size_t(t)] != ca[size_t(t)];
      EXPECT_NE(ca[size_t(t)], 1u) << "cluster without a basis is never chosen";
      worst = std::max(worst, std::fabs(re[size_t(t)] - ce[size_t(t)]) / (a.x2[size_t(t)] + 1.0));
    }
    EXPECT_EQ(differ, 0) << "d " << s.d;
    EXPECT_LE(worst, 1e-5) << "d " << s.d;
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
// falls back to the C++ references with a warning under --device auto. Its own process under
// ctest (gtest_discover_tests), so the broken programs are not cached for other tests.
TEST(OpenCLKernels, BrokenLpcaAndLpyrKernelsFallBack) {
  REQUIRE_CL();
  const std::string dir = ::testing::TempDir() + "btfc_broken_codec_kernels_" + std::to_string(::getpid());
  std::filesystem::create_directories(dir);
  std::filesystem::copy_file(std::string(BTFC_SOURCE_DIR) + "/kernels/btfc_shared.h", dir + "/btfc_shared.h",
                             std::filesystem::copy_options::overwrite_existing);
  std::ofstream(dir + "/lpca.cl") << "__kernel void lpca_project(__global float* x) { not C either }\n";
  std::ofstream(dir + "/lpyr.cl") << "__kernel void lpyr_reduce(__global float* x) { still not C }\n";
  setenv("BTFC_KERNEL_DIR", dir.c_str(), 1);
  AssignCase a = make_assign_case(19, 40, 3, 2, 1);
  std::vector<uint32_t> as(40, 0), ar(40, 0);
  std::vector<double> es(40), er(40);
  auto bad = lpca_cl::assign_cl(a.p, as.data(), es.data());
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), StatusCode::device_error);
  EXPECT_NE(bad.status().message().find("building OpenCL program lpca.cl failed"), std::string::npos) << bad.status().message();
  EXPECT_NE(bad.status().message().find("compiler log"), std::string::npos);
  std::vector<float> src(5 * 3 * 4, 1.f), dst(3 * 2 * 4);
  Status ls = lpyr::reduce_cl(src.data(), 5, 3, 4, dst.data());
  EXPECT_EQ(ls.code(), StatusCode::device_error);
  EXPECT_NE(ls.message().find("lpyr.cl"), std::string::npos) << ls.message();
  // --device cl: the dispatchers report the error; auto: they warn once and run the reference.
  ocl::set_device_choice(ocl::DeviceChoice::cl);
  EXPECT_FALSE(lpca_cl::assign(a.p, as.data(), es.data()).ok());
  EXPECT_FALSE(lpyr::reduce_any(src.data(), 5, 3, 4, dst.data()).ok());
  ocl::set_device_choice(ocl::DeviceChoice::automatic);
  std::fill(as.begin(), as.end(), 0u);
  auto got = lpca_cl::assign(a.p, as.data(), es.data());
  ASSERT_TRUE(got.ok());
  EXPECT_EQ(got.value(), lpca_cl::assign_reference(a.p, ar.data(), er.data()));
  EXPECT_EQ(as, ar);
  std::fill(dst.begin(), dst.end(), 0.f);
  ASSERT_TRUE(lpyr::reduce_any(src.data(), 5, 3, 4, dst.data()).ok());
  for (float v : dst) EXPECT_FLOAT_EQ(v, 1.f);  // box mean of a constant
  EXPECT_NE(ocl::fallback_reason().find(".cl"), std::string::npos) << ocl::fallback_reason();
  unsetenv("BTFC_KERNEL_DIR");
  std::filesystem::remove_all(dir);
}
