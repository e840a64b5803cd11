// The passes' thin products alone (core/thin_product.h), against OpenBLAS's sgemm on the same
// data in the same run (issue 24): for each width l, the best of 3 of
//   read    ||B||_F^2 (squared_norm: one read of B, the memory bound of a pass)
//   B X     thin_product (m x l)          and OpenBLAS on slices of rows
//   B^T Q   transposed_product (n x l)    and OpenBLAS on slices of texels
// and, once, the first pass's sparse sign sketches of B's rows (S^T B) and of its columns (B S),
// and the in-core SVD's whole first pass (B S G at l = 40).
// (OpenBLAS as btfc's fallback runs it: through Eigen, on 2 x threads OpenMP slices with one BLAS
// thread each; one OpenBLAS call on its own threads was 1.5-5 x slower at these widths.)
// with GFLOP/s (2 m n l per product). B is a --dump file of bench_fmf (the UBO2003 size: 19683 x
// 65536 float32, 5.16 GB), read into huge pages as the in-core SVD holds it, or random
// (--texels N columns of 19683 rows) when no file is given.
//
//   bench_products [--load FILE] [--rows 19683] [--texels 65536] [--widths "12 24 32 48 64 96"]
//                  [--ld LD]   (B is the first --rows rows of each LD-row column, as color=dfmf's
//                  in-place channels are: 6561 of 19683; --load files then hold LD-row columns)
#include <Eigen/Dense>
#include <cstdio>
#include <cstdlib>
#include <fcntl.h>
#include <omp.h>
#include <random>
#include <sstream>
#include <string>
#include <unistd.h>
#include <vector>

#include "bench/bench_timing.h"
#include "core/blas_env.h"
#include "core/cpu_dispatch.h"
#include "core/memory.h"
#include "core/sparse_sketch.h"
#include "core/svd.h"
#include "core/thin_product.h"

using namespace btfc;
using btfc::bench::best_of;

int main(int argc, char** argv) {
  std::string load, widths = "12 24 32 48 64 96";
  size_t m = 19683, n = 65536, ld = 0;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string a = argv[i];
    if (a == "--load") load = argv[i + 1];
    else if (a == "--rows") m = size_t(std::atoll(argv[i + 1]));
    else if (a == "--texels") n = size_t(std::atoll(argv[i + 1]));
    else if (a == "--widths") widths = argv[i + 1];
    else if (a == "--ld") ld = size_t(std::atoll(argv[i + 1]));
    else {
      std::fprintf(stderr, "bench_products: unknown option %s\n", a.c_str());
      return 2;
    }
  }
  if (ld < m) ld = m;
  if (!load.empty()) {
    const int fd = open(load.c_str(), O_RDONLY);
    const off_t size = fd >= 0 ? lseek(fd, 0, SEEK_END) : -1;
    if (fd < 0 || size <= 0 || size_t(size) % (4 * ld) != 0) {
      std::fprintf(stderr, "bench_products: %s: cannot open, or not a whole number of %zu-row float32 columns\n", load.c_str(), ld);
      return 1;
    }
    n = size_t(size) / (4 * ld);
    close(fd);
  }
  PageBuffer<float> buf(ld * n);
  if (!load.empty()) {
    const int fd = open(load.c_str(), O_RDONLY);
    char* p = reinterpret_cast<char*>(buf.data());
    for (size_t off = 0, total = ld * n * 4; off < total;) {
      const ssize_t r = read(fd, p + off, std::min<size_t>(total - off, size_t(1) << 26));
      if (r <= 0) {
        std::fprintf(stderr, "bench_products: %s: read failed\n", load.c_str());
        return 1;
      }
      off += size_t(r);
    }
    close(fd);
  } else {
    std::mt19937 rng(1);
    std::uniform_real_distribution<float> u(0.f, 1.f);
    for (size_t i = 0; i < ld * n; ++i) buf.data()[i] = u(rng);
  }
  const Eigen::Map<const Eigen::MatrixXf, 0, Eigen::OuterStride<>> B(buf.data(), Eigen::Index(m), Eigen::Index(n),
                                                                     Eigen::OuterStride<>(Eigen::Index(ld)));
  std::printf("B: %zu x %zu float32 (%.2f GB, leading dimension %zu)%s, loops: %s\n", m, n, double(m * n) * 4 / 1e9, ld,
              load.empty() ? " random" : "", cpu_dispatch_level());
  if (ld == m) {  // the sparse sign sketches of the first pass (s = 256 buckets, two per row or column)
    const size_t sk = 256, chunk = 4096;
    const SparseSign rows_s = make_sparse_sign(m, sk, 1, 2), cols_s = make_sparse_sign(n, sk, 1, 2);
    PageBuffer<float> wr(sk * chunk), wc(m * sk);
    double e = 0;
    const double t_rows = best_of(3, [&] {
      for (size_t j0 = 0; j0 < n; j0 += chunk) sparse_sign_product(buf.data() + j0 * m, std::min(chunk, n - j0), rows_s, wr.data(), &e);
    });
    const double t_cols = best_of(3, [&] { sparse_sign_columns(buf.data(), m, m, n, cols_s, wc.data(), &e); });
    const SparseSign cols_1 = make_sparse_sign(n, sk, 1, 1);
    const double t_cols1 = best_of(3, [&] { sparse_sign_columns(buf.data(), m, m, n, cols_1, wc.data(), &e); });
    std::printf("sparse sign sketches (s = %zu, with ||B||^2): rows S^T B %.3f s, columns B S %.3f s (one per column: %.3f s)%s\n", sk,
                t_rows, t_cols, t_cols1, e < 0 ? " " : "");
    // The first pass as the in-core block Krylov SVD runs it (svd.h column_sketch_product: B S by
    // blocks of rows, then times the Gaussian G), at fmf's rank 32 + oversample 8.
    SvdOptions o;
    o.seed = 1;
    const Sketch first = make_column_sketch(n, 40, o);
    Eigen::MatrixXf Y(Eigen::Index(m), 40);
    std::vector<float> scratch;
    const double t_first = best_of(3, [&] { column_sketch_product(buf.data(), m, n, first, Y, &e, 0, &scratch); });
    std::printf("first pass Y = B S G (l = 40, s = %zu, %s, with ||B||^2): %.3f s\n", first.S.s, first.sparse() ? "sparse" : "dense", t_first);
  }
  std::printf("%4s %8s | %8s %6s %8s %6s %8s %6s | %8s %6s %8s %6s\n", "l", "read s", "B X s", "GF/s", "OpenBLAS", "GF/s", "tiles",
              "GF/s", "B^T Q s", "GF/s", "OpenBLAS", "GF/s");
  std::istringstream ws(widths);
  for (int l; ws >> l;) {
    Eigen::MatrixXf X = Eigen::MatrixXf::Random(Eigen::Index(n), l), Q = Eigen::MatrixXf::Random(Eigen::Index(m), l);
    Eigen::MatrixXf Y(Eigen::Index(m), l), Z(Eigen::Index(n), l);
    double sink = 0;
    const double t_read = best_of(3, [&] { sink += squared_norm(buf.data(), m, n, ld); });
    const double t_nn = best_of(3, [&] { thin_product(buf.data(), m, n, X, Y, ld); });
    Eigen::MatrixXf Yt;
    // The tile kernels alone (on Intel's AVX-512 CPUs B X is OpenBLAS's): AVX-512's, else AVX2's.
    bool tiles_ran = false;
    const double t_tiles = best_of(3, [&] {
      tiles_ran = cpu_has_avx512f() ? thin_product_tiles(buf.data(), m, n, X, Yt, ld) : thin_product_avx2(buf.data(), m, n, X, Yt, ld);
    });
    const int parts = 2 * omp_get_max_threads();
    const double t_nn_blas = best_of(3, [&] {
      SingleThreadedBlas one;
#pragma omp parallel for schedule(dynamic, 1)
      for (int p = 0; p < parts; ++p) {
        const Eigen::Index r0 = Eigen::Index(m) * p / parts, r1 = Eigen::Index(m) * (p + 1) / parts;
        Y.middleRows(r0, r1 - r0).noalias() = B.middleRows(r0, r1 - r0) * X;
      }
    });
    const double t_tn = best_of(3, [&] { transposed_product(buf.data(), m, n, Q, Z, nullptr, ld); });
    const double t_tn_blas = best_of(3, [&] {
      SingleThreadedBlas one;
#pragma omp parallel for schedule(dynamic, 1)
      for (int p = 0; p < parts; ++p) {
        const Eigen::Index j0 = Eigen::Index(n) * p / parts, j1 = Eigen::Index(n) * (p + 1) / parts;
        Z.middleRows(j0, j1 - j0).noalias() = B.middleCols(j0, j1 - j0).transpose() * Q;
      }
    });
    const double gf = 2.0 * double(m) * double(n) * double(l) / 1e9;
    char tiles[32] = "       -      -";
    if (tiles_ran) std::snprintf(tiles, sizeof tiles, "%8.3f %6.0f", t_tiles, gf / t_tiles);
    std::printf("%4d %8.3f | %8.3f %6.0f %8.3f %6.0f %s | %8.3f %6.0f %8.3f %6.0f%s\n", l, t_read, t_nn, gf / t_nn, t_nn_blas,
                gf / t_nn_blas, tiles, t_tn, gf / t_tn, t_tn_blas, gf / t_tn_blas, sink < 0 ? " " : "");
  }
  return 0;
}
