// lpca OpenCL host code and C++ references; see lpca_cl.h.
#include "codecs/lpca/lpca_cl.h"

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <limits>
#include <omp.h>

#include "core/blas_env.h"
#include "core/cl_runtime.h"

namespace btfc::lpca_cl {
namespace {

using MatrixXfR = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// The selection of one texel from its projections p (K groups of c + 1); the kernel lpca_select
// does the same arithmetic.
int select(const AssignProblem& pr, const float* p, size_t t, uint32_t* assign, double* err) {
  const int K = pr.K, c = pr.c;
  const uint32_t cur = assign[t];
  double best = std::numeric_limits<double>::infinity(), cur_e = best;
  uint32_t best_k = cur;
  for (int k = 0; k < K; ++k) {
    const double m2 = pr.mu2[size_t(k)];
    if (m2 < 0) continue;
    double e = pr.x2[t] - 2.0 * double(p[k * (c + 1)]) + m2;
    for (int j = 0; j < c; ++j) {
      const double q = double(p[k * (c + 1) + 1 + j]) - pr.muE[size_t(k) * size_t(c) + size_t(j)];
      e -= q * q;
    }
    e = std::max(0.0, e);
    if (uint32_t(k) == cur) cur_e = e;
    if (e < best) best = e, best_k = uint32_t(k);
  }
  if (best_k != cur && best < cur_e - pr.margin * (pr.x2[t] + pr.mu2[best_k])) {
    assign[t] = best_k;
    err[t] = best;
    return 1;
  }
  err[t] = std::isfinite(cur_e) ? cur_e : best;
  return 0;
}

#define BTFC_CL_CHECK(call, what)                                                                                      \
  do {                                                                                                                 \
    cl_int e_ = (call);                                                                                                \
    if (e_ != CL_SUCCESS) return Status(StatusCode::device_error, std::string(what) + ": " + ocl::cl_error_name(e_)); \
  } while (0)

template <class T>
Status set_arg(cl_kernel k, int i, const T& v, const char* name) {
  BTFC_CL_CHECK(clSetKernelArg(k, cl_uint(i), sizeof(T), &v), name);
  return {};
}

// Directions per lpca_project launch: the chunk of W (k_chunk x Mp floats, 0.3-1.2 MB for
// 72-288 projections) stays in the core's cache while all texel groups pass over it.
constexpr int k_chunk = 1024;

}  // namespace

int assign_reference(const AssignProblem& pr, uint32_t* assign, double* err) {
  const Eigen::Index d = pr.d, N = pr.N, M = Eigen::Index(pr.K) * (pr.c + 1);
  const Eigen::Map<const Eigen::MatrixXf> X(pr.X, d, N), W(pr.W, d, M);
  // Texel blocks in parallel, each block's GEMM single-threaded (Eigen does not nest inside an
  // OpenMP region; OpenBLAS is held to one thread, core/blas_env.h): one fork/join per step
  // instead of fine-grained GEMM synchronisation, which ran 3-15x slower than one thread when
  // the 2-core machine was shared.
  int moved = 0;
  const Eigen::Index tb = 512;
  SingleThreadedBlas one_blas_thread;
#pragma omp parallel reduction(+ : moved)
  {
    MatrixXfR P(tb, M);
#pragma omp for schedule(dynamic, 1)
    for (Eigen::Index t0 = 0; t0 < N; t0 += tb) {
      const Eigen::Index nb = std::min(tb, N - t0);
      P.topRows(nb).noalias() = X.middleCols(t0, nb).transpose() * W;  // nb x K(c+1)
      for (Eigen::Index i = 0; i < nb; ++i) moved += select(pr, P.data() + i * M, size_t(t0 + i), assign, err);
    }
  }
  return moved;
}

Result<int> assign_cl(const AssignProblem& pr, uint32_t* assign, double* err) {
  BTFC_ASSIGN_OR_RETURN(ocl::Runtime * rt, ocl::Runtime::get());
  BTFC_ASSIGN_OR_RETURN(cl_command_queue queue, rt->queue());
  BTFC_ASSIGN_OR_RETURN(cl_kernel kp, rt->kernel("lpca", "lpca_project"));
  BTFC_ASSIGN_OR_RETURN(cl_kernel ks, rt->kernel("lpca", "lpca_select"));
  const size_t d = size_t(pr.d), N = size_t(pr.N), M = size_t(pr.K) * size_t(pr.c + 1);
  const int strips = int((M + 15) / 16);
  const size_t Mp = size_t(strips) * 16;
  // W in strips of 16 projection vectors, [strip][r][16], zero-padded to Mp.
  std::vector<float> Ws(size_t(strips) * d * 16, 0.0f);
#pragma omp parallel for schedule(static)
  for (int s = 0; s < strips; ++s)
    for (size_t j = 0; j < 16 && size_t(s) * 16 + j < M; ++j) {
      const float* col = pr.W + (size_t(s) * 16 + j) * d;
      for (size_t r = 0; r < d; ++r) Ws[(size_t(s) * d + r) * 16 + j] = col[r];
    }
  // Texel blocks of <= 256 MiB of ABRDFs (the device's allocation limit is 1-2 GiB, toolchain.md 3).
  const size_t nb_max = std::clamp<size_t>((size_t(256) << 20) / (d * 4), 8, N);
  BTFC_ASSIGN_OR_RETURN(ocl::Buffer ws, ocl::Buffer::create(*rt, Ws.size() * 4, Ws.data(), CL_MEM_READ_ONLY));
  BTFC_ASSIGN_OR_RETURN(ocl::Buffer pb, ocl::Buffer::create(*rt, nb_max * Mp * 4, nullptr, CL_MEM_READ_WRITE));
  BTFC_ASSIGN_OR_RETURN(ocl::Buffer mu2, ocl::Buffer::create(*rt, pr.mu2.size() * 8, pr.mu2.data(), CL_MEM_READ_ONLY));
  std::vector<double> muE_pad(pr.muE);
  if (muE_pad.empty()) muE_pad.push_back(0);
  BTFC_ASSIGN_OR_RETURN(ocl::Buffer mue, ocl::Buffer::create(*rt, muE_pad.size() * 8, muE_pad.data(), CL_MEM_READ_ONLY));
  std::vector<int> moved_flags(nb_max);
  int moved = 0;
  for (size_t t0 = 0; t0 < N; t0 += nb_max) {
    const size_t nb = std::min(nb_max, N - t0);
    BTFC_ASSIGN_OR_RETURN(ocl::Buffer xb, ocl::Buffer::wrap(*rt, nb * d * 4, const_cast<float*>(pr.X + t0 * d), CL_MEM_READ_ONLY));
    const cl_mem xm = xb.get(), wm = ws.get(), pm = pb.get();
    const cl_int di = cl_int(d), si = strips, ni = cl_int(nb);
    for (size_t r0 = 0; r0 < d; r0 += k_chunk) {
      const cl_int r0i = cl_int(r0), rci = cl_int(std::min<size_t>(k_chunk, d - r0)), first = r0 == 0;
      BTFC_RETURN_IF_ERROR(set_arg(kp, 0, xm, "lpca_project"));
      BTFC_RETURN_IF_ERROR(set_arg(kp, 1, di, "lpca_project"));
      BTFC_RETURN_IF_ERROR(set_arg(kp, 2, wm, "lpca_project"));
      BTFC_RETURN_IF_ERROR(set_arg(kp, 3, si, "lpca_project"));
      BTFC_RETURN_IF_ERROR(set_arg(kp, 4, r0i, "lpca_project"));
      BTFC_RETURN_IF_ERROR(set_arg(kp, 5, rci, "lpca_project"));
      BTFC_RETURN_IF_ERROR(set_arg(kp, 6, ni, "lpca_project"));
      BTFC_RETURN_IF_ERROR(set_arg(kp, 7, first, "lpca_project"));
      BTFC_RETURN_IF_ERROR(set_arg(kp, 8, pm, "lpca_project"));
      const size_t global = (nb + 7) / 8;
      BTFC_CL_CHECK(clEnqueueNDRangeKernel(queue, kp, 1, nullptr, &global, nullptr, 0, nullptr, nullptr), "lpca_project");
    }
    BTFC_ASSIGN_OR_RETURN(ocl::Buffer x2b, ocl::Buffer::wrap(*rt, nb * 8, const_cast<double*>(pr.x2 + t0), CL_MEM_READ_ONLY));
    BTFC_ASSIGN_OR_RETURN(ocl::Buffer ab, ocl::Buffer::wrap(*rt, nb * 4, assign + t0, CL_MEM_READ_WRITE));
    BTFC_ASSIGN_OR_RETURN(ocl::Buffer eb, ocl::Buffer::wrap(*rt, nb * 8, err + t0, CL_MEM_WRITE_ONLY));
    BTFC_ASSIGN_OR_RETURN(ocl::Buffer mb, ocl::Buffer::wrap(*rt, nb * 4, moved_flags.data(), CL_MEM_WRITE_ONLY));
    const cl_mem m2m = mu2.get(), mem = mue.get(), x2m = x2b.get(), am = ab.get(), em = eb.get(), mm = mb.get();
    const cl_int Mpi = cl_int(Mp), Ki = pr.K, ci = pr.c;
    const cl_double margin = pr.margin;
    int a = 0;
    BTFC_RETURN_IF_ERROR(set_arg(ks, a++, pm, "lpca_select"));
    BTFC_RETURN_IF_ERROR(set_arg(ks, a++, Mpi, "lpca_select"));
    BTFC_RETURN_IF_ERROR(set_arg(ks, a++, Ki, "lpca_select"));
    BTFC_RETURN_IF_ERROR(set_arg(ks, a++, ci, "lpca_select"));
    BTFC_RETURN_IF_ERROR(set_arg(ks, a++, m2m, "lpca_select"));
    BTFC_RETURN_IF_ERROR(set_arg(ks, a++, mem, "lpca_select"));
    BTFC_RETURN_IF_ERROR(set_arg(ks, a++, x2m, "lpca_select"));
    BTFC_RETURN_IF_ERROR(set_arg(ks, a++, margin, "lpca_select"));
    BTFC_RETURN_IF_ERROR(set_arg(ks, a++, ni, "lpca_select"));
    BTFC_RETURN_IF_ERROR(set_arg(ks, a++, am, "lpca_select"));
    BTFC_RETURN_IF_ERROR(set_arg(ks, a++, em, "lpca_select"));
    BTFC_RETURN_IF_ERROR(set_arg(ks, a++, mm, "lpca_select"));
    const size_t global = nb;
    BTFC_CL_CHECK(clEnqueueNDRangeKernel(queue, ks, 1, nullptr, &global, nullptr, 0, nullptr, nullptr), "lpca_select");
    BTFC_RETURN_IF_ERROR(ab.sync_to_host(queue, nb * 4));
    BTFC_RETURN_IF_ERROR(eb.sync_to_host(queue, nb * 8));
    BTFC_RETURN_IF_ERROR(mb.sync_to_host(queue, nb * 4));
    for (size_t i = 0; i < nb; ++i) moved += moved_flags[i];
  }
  return moved;
}

Result<int> assign(const AssignProblem& p, uint32_t* a, double* e) {
  if (ocl::use_opencl()) {
    // The kernels write assign / err only for texels they finish; on a failure mid-way the
    // reference redoes every texel from the same inputs, so the result is the same either way.
    std::vector<uint32_t> saved(a, a + p.N);
    Result<int> r = assign_cl(p, a, e);
    if (r.ok() || !ocl::fall_back_after(r.status())) return r;
    std::copy(saved.begin(), saved.end(), a);
  }
  return assign_reference(p, a, e);
}

void relight_reference(std::span<const uint32_t> cluster, const float* W, int c, const float* L, float* out) {
#pragma omp parallel for schedule(static)
  for (size_t t = 0; t < cluster.size(); ++t) {
    const size_t r0 = size_t(cluster[t]) * size_t(c + 1);
    for (int ch = 0; ch < 3; ++ch) {
      float s = L[r0 * 3 + size_t(ch)];
      for (int i = 0; i < c; ++i) s += W[t * size_t(c) + size_t(i)] * L[(r0 + 1 + size_t(i)) * 3 + size_t(ch)];
      out[t * 3 + size_t(ch)] = s;
    }
  }
}

Status relight_cl(std::span<const uint32_t> cluster, const float* W, int c, const float* L, size_t L_rows, float* out) {
  BTFC_ASSIGN_OR_RETURN(ocl::Runtime * rt, ocl::Runtime::get());
  BTFC_ASSIGN_OR_RETURN(cl_command_queue queue, rt->queue());
  BTFC_ASSIGN_OR_RETURN(cl_kernel k, rt->kernel("lpca", "lpca_relight"));
  const size_t n = cluster.size();
  if (n == 0) return {};
  BTFC_ASSIGN_OR_RETURN(ocl::Buffer cb, ocl::Buffer::wrap(*rt, n * 4, const_cast<uint32_t*>(cluster.data()), CL_MEM_READ_ONLY));
  BTFC_ASSIGN_OR_RETURN(ocl::Buffer wb, ocl::Buffer::wrap(*rt, std::max<size_t>(1, n * size_t(c)) * 4, const_cast<float*>(W), CL_MEM_READ_ONLY));
  BTFC_ASSIGN_OR_RETURN(ocl::Buffer lb, ocl::Buffer::create(*rt, L_rows * 3 * 4, L, CL_MEM_READ_ONLY));
  BTFC_ASSIGN_OR_RETURN(ocl::Buffer ob, ocl::Buffer::wrap(*rt, n * 12, out, CL_MEM_WRITE_ONLY));
  const cl_mem cm = cb.get(), wm = wb.get(), lm = lb.get(), om = ob.get();
  const cl_int ci = c, ni = cl_int(n);
  BTFC_RETURN_IF_ERROR(set_arg(k, 0, cm, "lpca_relight"));
  BTFC_RETURN_IF_ERROR(set_arg(k, 1, wm, "lpca_relight"));
  BTFC_RETURN_IF_ERROR(set_arg(k, 2, ci, "lpca_relight"));
  BTFC_RETURN_IF_ERROR(set_arg(k, 3, lm, "lpca_relight"));
  BTFC_RETURN_IF_ERROR(set_arg(k, 4, ni, "lpca_relight"));
  BTFC_RETURN_IF_ERROR(set_arg(k, 5, om, "lpca_relight"));
  const size_t local = 64, global = (n + local - 1) / local * local;
  BTFC_CL_CHECK(clEnqueueNDRangeKernel(queue, k, 1, nullptr, &global, &local, 0, nullptr, nullptr), "lpca_relight");
  return ob.sync_to_host(queue, n * 12);
}

Status relight(std::span<const uint32_t> cluster, const float* W, int c, const float* L, size_t L_rows, float* out) {
  if (ocl::use_opencl()) {
    Status s = relight_cl(cluster, W, c, L, L_rows, out);
    if (s.ok() || !ocl::fall_back_after(s)) return s;
  }
  relight_reference(cluster, W, c, L, out);
  return {};
}

}  // namespace btfc::lpca_cl
