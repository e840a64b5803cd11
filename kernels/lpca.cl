/* lpca kernels (codecs/lpca/lpca_cl.h is the host side, its *_reference functions the C++ truth).
   Written CPU-style for PoCL (toolchain.md 3): straight loops, float16 vectors, register
   blocking, no local memory and no barriers. */
#pragma OPENCL EXTENSION cl_khr_fp64 : enable

/* Assignment step, part 1 (clustering.h step c): projections of a block of texels onto every
   cluster's mean and eigen-BRDFs, P[t][m] (+)= sum_{r0 <= r < r0 + rc} X[t][r] W[r][m].
   Ws holds W in strips of 16 projection vectors, [strip][r][16], so a strip's rows stream
   contiguously; X is texel-major (texel t at X + t d). The host runs one launch per chunk of
   rc directions so the chunk of Ws (rc x Mp floats) stays in the core's cache while every
   texel group passes over it; P carries the partial sums between chunks (first = overwrite).
   A work-item owns 8 texels: each float16 load of Ws feeds 8 FMAs (register blocking). */
__kernel void lpca_project(__global const float* X, int d, __global const float* Ws, int strips, int r0, int rc, int n,
                           int first, __global float* P) {
  int t0 = get_global_id(0) * 8;
  if (t0 >= n) return;
  int Mp = strips * 16;
  if (t0 + 8 <= n) {
    __global const float* x = X + (size_t)t0 * d + r0;
    for (int s = 0; s < strips; ++s) {
      __global float* p = P + (size_t)t0 * Mp + s * 16;
      float16 a0 = (float16)(0.0f), a1 = a0, a2 = a0, a3 = a0, a4 = a0, a5 = a0, a6 = a0, a7 = a0;
      if (!first) {
        a0 = vload16(0, p), a1 = vload16(0, p + Mp), a2 = vload16(0, p + 2 * Mp), a3 = vload16(0, p + 3 * Mp);
        a4 = vload16(0, p + 4 * Mp), a5 = vload16(0, p + 5 * Mp), a6 = vload16(0, p + 6 * Mp), a7 = vload16(0, p + 7 * Mp);
      }
      __global const float* w = Ws + ((size_t)s * d + r0) * 16;
      for (int r = 0; r < rc; ++r) {
        float16 wv = vload16(r, w);
        a0 = mad((float16)(x[r]), wv, a0);
        a1 = mad((float16)(x[d + r]), wv, a1);
        a2 = mad((float16)(x[2 * d + r]), wv, a2);
        a3 = mad((float16)(x[3 * d + r]), wv, a3);
        a4 = mad((float16)(x[4 * d + r]), wv, a4);
        a5 = mad((float16)(x[5 * d + r]), wv, a5);
        a6 = mad((float16)(x[6 * d + r]), wv, a6);
        a7 = mad((float16)(x[7 * d + r]), wv, a7);
      }
      vstore16(a0, 0, p), vstore16(a1, 0, p + Mp), vstore16(a2, 0, p + 2 * Mp), vstore16(a3, 0, p + 3 * Mp);
      vstore16(a4, 0, p + 4 * Mp), vstore16(a5, 0, p + 5 * Mp), vstore16(a6, 0, p + 6 * Mp), vstore16(a7, 0, p + 7 * Mp);
    }
    return;
  }
  for (int t = t0; t < n; ++t) {  // the block's last, partial group of texels
    __global const float* x = X + (size_t)t * d + r0;
    for (int s = 0; s < strips; ++s) {
      __global float* p = P + (size_t)t * Mp + s * 16;
      float16 a = first ? (float16)(0.0f) : vload16(0, p);
      __global const float* w = Ws + ((size_t)s * d + r0) * 16;
      for (int r = 0; r < rc; ++r) a = mad((float16)(x[r]), vload16(r, w), a);
      vstore16(a, 0, p);
    }
  }
}

/* Assignment step, part 2: per texel, the reconstruction error in every valid cluster k,
     e_k = ||x||^2 - 2 <x, mu_k> + ||mu_k||^2 - sum_j (<x, E_kj> - <mu_k, E_kj>)^2,
   in double (a difference of large terms), and the best cluster. The texel moves only when the
   best beats its current cluster by more than margin (||x||^2 + ||mu_best||^2): float rounding
   of P must not make the assignment oscillate. P row t: K groups of (c + 1) projections. */
__kernel void lpca_select(__global const float* P, int Mp, int K, int c, __global const double* mu2,
                          __global const double* muE, __global const double* x2, double margin, int n,
                          __global uint* assign, __global double* err, __global int* moved) {
  int t = get_global_id(0);
  if (t >= n) return;
  __global const float* p = P + (size_t)t * Mp;
  uint cur = assign[t], best_k = cur;
  double best = INFINITY, cur_e = INFINITY, xx = x2[t];
  for (int k = 0; k < K; ++k) {
    double m2 = mu2[k];
    if (m2 < 0) continue;  /* invalid cluster */
    double e = xx - 2.0 * (double)p[k * (c + 1)] + m2;
    for (int j = 0; j < c; ++j) {
      double q = (double)p[k * (c + 1) + 1 + j] - muE[k * c + j];
      e -= q * q;
    }
    e = max(0.0, e);
    if ((uint)k == cur) cur_e = e;
    if (e < best) best = e, best_k = (uint)k;
  }
  int mv = 0;
  if (best_k != cur && best < cur_e - margin * (xx + mu2[best_k])) {
    assign[t] = best_k;
    err[t] = best;
    mv = 1;
  } else {
    err[t] = isfinite(cur_e) ? cur_e : best;
  }
  moved[t] = mv;
}

/* Relighting (seed 002 eq. 2-3, codecs/lpca/relight.cpp): radiance of texel t for one view and
   the environment, out[t][ch] = L[r0][ch] + sum_i w[t][i] L[r0 + 1 + i][ch] with r0 = cluster(t)
   (c + 1); L[row][ch] are the table rows' SH coefficients dotted with the lighting and blended
   over the view triangle (computed once per view on the host). */
__kernel void lpca_relight(__global const uint* cluster, __global const float* W, int c, __global const float* L, int n,
                           __global float* out) {
  int t = get_global_id(0);
  if (t >= n) return;
  size_t r0 = (size_t)cluster[t] * (c + 1);
  __global const float* w = W + (size_t)t * c;
  __global const float* l = L + r0 * 3;
  float3 s = vload3(0, l);
  for (int i = 0; i < c; ++i) s = mad((float3)(w[i]), vload3(0, l + 3 * (i + 1)), s);
  vstore3(s, t, out);
}
