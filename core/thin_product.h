// Thin products with a large float matrix B held in place: the passes of the randomized SVD
// (core/svd.h) and of the out-of-core path. B is m x n column-major (leading dimension m), the
// data itself, never copied or packed; the other operand has l columns, l small (~8-150).
//
// Why our own kernels: a general GEMM (OpenBLAS) packs B, the large operand, into its own
// layout on every call, which for l = 32-80 columns is a large part of the product's time, and
// its thread pool spins beside the OpenMP one (docs/benchmarks.md, "fmf factorization"). These
// kernels read B once, stream it sequentially with software prefetch, and keep the small
// operand in L1/L2. They are AVX-512 or AVX2, chosen at run time: B^T Y for l <= 128 in
// AVX-512, <= 96 in AVX2; B X for l <= 128 in AVX-512 on AMD CPUs, in AVX2 on Zen 1 only, where
// they were measured faster than OpenBLAS. Elsewhere (another CPU, wider l: thin_product.cpp)
// the products are Eigen products (OpenBLAS when linked) on slices of B in OpenMP threads, one
// BLAS thread each (OpenBLAS's own pool spins against the OpenMP threads of the code around).
// Float sums in a fixed order per output, so a result does not depend on the thread count;
// within GEMM round-off of the reference products.
#pragma once
#include <Eigen/Core>
#include <cstddef>
#include <memory>

namespace btfc {

// Z = B^T Y: Z n x l, Y m x l. With `energy`, also *energy = ||B||_F^2 (= squared_norm(B, m n)
// to round-off; the kernel sums it during the pass, from cache). A MatrixXf Z is resized; a Ref
// (a map of the caller's memory, e.g. huge pages) must already be n x l. `ldb`: B's leading
// dimension when B is the first m rows of a taller matrix (0: m); the same bits either way.
using ConstRefF = Eigen::Ref<const Eigen::MatrixXf>;
void transposed_product(const float* B, size_t m, size_t n, const ConstRefF& Y, Eigen::Ref<Eigen::MatrixXf> Z, double* energy = nullptr,
                        size_t ldb = 0);
void transposed_product(const float* B, size_t m, size_t n, const ConstRefF& Y, Eigen::MatrixXf& Z, double* energy = nullptr,
                        size_t ldb = 0);

// Y of B^T Y made ready once for several products with the same Y (the parts and chunks of a
// pass): the kernels read Y row-major and zero-padded, a copy (1.3 MB at m = 6561, l = 48) that,
// made by every call, ran on the calling thread while the other waited: 10-20 % of that thread's
// time in a color=dfmf encode's B^T Q passes (docs/benchmarks.md). Holds its own copy: Y may
// change or go afterwards.
class StagedY {
 public:
  explicit StagedY(const ConstRefF& Y);
  ~StagedY();
  StagedY(StagedY&&) noexcept;
  StagedY& operator=(StagedY&&) noexcept;
  Eigen::Index rows() const;
  Eigen::Index cols() const;
  struct Impl;
  const Impl& impl() const { return *m_impl; }
  Impl& impl() { return *m_impl; }

 private:
  std::unique_ptr<Impl> m_impl;
};
// The same product and bits as the call with Y itself; Y.rows() must be m.
void transposed_product(const float* B, size_t m, size_t n, const StagedY& Y, Eigen::Ref<Eigen::MatrixXf> Z, double* energy = nullptr,
                        size_t ldb = 0);

// For tests: transposed_product through its AVX2 kernel (the one CPUs without AVX-512 run for
// l <= 96) on any CPU with AVX2 + FMA. Returns false where that kernel does not apply (Z is then
// resized to n x l but not written).
bool transposed_product_avx2(const float* B, size_t m, size_t n, const ConstRefF& Y, Eigen::MatrixXf& Z, double* energy = nullptr,
                             size_t ldb = 0);

// Y = B X: Y m x l, X n x l, different memory. A MatrixXf Y is resized; a Ref must be m x l.
// `ldb` as above (0: m).
void thin_product(const float* B, size_t m, size_t n, const ConstRefF& X, Eigen::Ref<Eigen::MatrixXf> Y, size_t ldb = 0);
void thin_product(const float* B, size_t m, size_t n, const ConstRefF& X, Eigen::MatrixXf& Y, size_t ldb = 0);
// For tests: thin_product through the AVX-512 tiles on any CPU with AVX-512 (Intel's take
// OpenBLAS in thin_product). Returns false where the tiles do not apply (Y resized, not written).
bool thin_product_tiles(const float* B, size_t m, size_t n, const ConstRefF& X, Eigen::MatrixXf& Y, size_t ldb = 0);
// For tests: thin_product through the AVX2 tiles (the ones Zen 1 CPUs run) on any CPU
// with AVX2 + FMA. Returns false where they do not apply (Y resized, not written).
bool thin_product_avx2(const float* B, size_t m, size_t n, const ConstRefF& X, Eigen::MatrixXf& Y, size_t ldb = 0);

// ||B||_F^2 over `count` floats, summed in double (vectorized, parallel, fixed block order).
double squared_norm(const float* B, size_t count);
// The same for B m x n with leading dimension ldb (ldb = m: the call above; else column by
// column, the columns' sums added in order: independent of the thread count).
double squared_norm(const float* B, size_t m, size_t n, size_t ldb);

}  // namespace btfc
