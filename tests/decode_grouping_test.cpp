// Decoding is bitwise independent of how it is grouped: a model decoded in bands of texel rows
// (streamed decompress, out-of-core compare) gives the same bytes as one whole decode, on the
// C++ path, whatever BLAS kernel the machine has (core/fixed_product.h; issue 23: a streamed
// decode differed from the whole one by one ulp on another CPU's OpenBLAS kernels).
#include <gtest/gtest.h>

#include <cstring>
#include <random>

#include "codecs/codec.h"
#include "core/cl_runtime.h"
#include "core/fixed_product.h"
#include "core/synth.h"

using namespace btfc;

namespace {

struct CpuOnly {  // the C++ path: the OpenCL kernels are checked against it elsewhere
  ocl::DeviceChoice saved = ocl::device_choice();
  CpuOnly() { ocl::set_device_choice(ocl::DeviceChoice::cpu); }
  ~CpuOnly() { ocl::set_device_choice(saved); }
};

std::vector<float> random_vec(size_t n, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<float> g(0, 1);
  std::vector<float> v(n);
  for (float& x : v) x = g(rng);
  return v;
}

}  // namespace

TEST(FixedProduct, RowsDoNotDependOnTheirGroupAndMatchDouble) {
  // Sizes that exercise the full 4 x 32 blocks and both ragged edges.
  const size_t n = 23, C = 37, m = 101;
  const auto A = random_vec(n * C, 1), BT = random_vec(C * m, 2);
  std::vector<float> whole(n * m), parts(n * m, -1.0f);
  fixed_order_product(A.data(), n, C, C, BT.data(), m, whole.data(), m);
  for (size_t r0 = 0, step = 1; r0 < n; r0 += step, step = step % 5 + 1)
    fixed_order_product(A.data() + r0 * C, std::min(step, n - r0), C, C, BT.data(), m, parts.data() + r0 * m, m);
  EXPECT_EQ(std::memcmp(whole.data(), parts.data(), whole.size() * sizeof(float)), 0);
  // Against a double-precision product: within the float dot-product bound C * eps * sum |a b|.
  double worst = 0;
  for (size_t i = 0; i < n; ++i)
    for (size_t r = 0; r < m; ++r) {
      double exact = 0, mag = 0;
      for (size_t k = 0; k < C; ++k) exact += double(A[i * C + k]) * BT[k * m + r], mag += std::fabs(double(A[i * C + k]) * BT[k * m + r]);
      worst = std::max(worst, std::fabs(whole[i * m + r] - exact) / (double(C) * 0x1p-24 * mag));
    }
  EXPECT_LE(worst, 1.0);
  EXPECT_GT(worst, 0.0);  // float arithmetic, not a double product in disguise
  // accumulate = true adds the product to what is there.
  std::vector<float> acc(whole);
  fixed_order_product(A.data(), n, C, C, BT.data(), m, acc.data(), m, true);
  for (size_t i = 0; i < acc.size(); i += 97) EXPECT_NEAR(acc[i], 2 * whole[i], 1e-4f * (1 + std::fabs(whole[i])));
}

TEST(DecodeGrouping, BandsEqualTheWholeDecodeBitForBit) {
  CpuOnly cpu;
  SynthOptions sp;
  sp.width = 37, sp.height = 29, sp.seed = 5;
  auto subset = [](size_t n, size_t step) {
    DirectionSet all = DirectionSet::ubo2003(), d;
    d.name = "custom";
    for (size_t i = 0; i < n; ++i) d.dirs.push_back(all.dirs[(i * step) % all.size()]);
    return d;
  };
  sp.lights = subset(9, 7), sp.views = subset(4, 11);
  auto b = synthesize_btf(sp);
  ASSERT_TRUE(b.ok()) << b.status().message();
  for (const char* spec : {"fmf:rank=7", "fmf:rank=6:color=dfmf:chroma_rank=3", "lpyr", "lpca:clusters=3:components=4"}) {
    auto r = resolve_spec(spec);
    ASSERT_TRUE(r.ok()) << spec << ": " << r.status().message();
    Context ctx;
    auto model = r->first->encode(*b, r->second, ctx);
    ASSERT_TRUE(model.ok()) << spec << ": " << model.status().message();
    Btf whole;
    ASSERT_TRUE((*model)->decode_all(whole).ok());
    const size_t row_values = size_t(sp.width) * whole.desc().abrdf_size();
    size_t mismatched_bands = 0;
    for (int y0 = 0, h = 1; y0 < sp.height; y0 += h, h = h % 6 + 2) {
      DecodeRequest q;
      q.y0 = y0, q.height = std::min(h, sp.height - y0);
      Btf band;
      ASSERT_TRUE((*model)->decode(q, band).ok()) << spec;
      ASSERT_EQ(band.size(), size_t(q.height) * row_values);
      mismatched_bands += std::memcmp(band.data(), whole.data() + size_t(y0) * row_values, band.size() * sizeof(float)) != 0;
    }
    EXPECT_EQ(mismatched_bands, 0u) << spec;
  }
}
