/* lpca kernels (codecs/lpca/lpca_cl.h is the host side, its *_reference functions the C++ truth).
   Written CPU-style for PoCL (toolchain.md 3): straight loops, float16 vectors, register
   blocking, no local memory and no barriers. */

/* Sum of the 16 lanes. */
inline float hsum16(float16 v) {
  float8 a = v.lo + v.hi;
  float4 b = a.lo + a.hi;
  float2 c = b.lo + b.hi;
  return c.x + c.y;
}

#define LPCA_ROW(i, xp)           \
  x = vload16(0, xp + r);         \
  a##i##0 = mad(x, v0, a##i##0); \
  a##i##1 = mad(x, v1, a##i##1); \
  a##i##2 = mad(x, v2, a##i##2);

#define LPCA_STORE(i, xp)                                                                              \
  {                                                                                                    \
    float s0 = hsum16(a##i##0), s1 = hsum16(a##i##1), s2 = hsum16(a##i##2);                          \
    for (int t = r16; t < rc; ++t) s0 = mad(xp[t], w0[t], s0), s1 = mad(xp[t], w1[t], s1), s2 = mad(xp[t], w2[t], s2); \
    __global float* q = o + (i) * V + j;                                                               \
    if (first) q[0] = s0, q[1] = s1, q[2] = s2;                                                        \
    else q[0] += s0, q[1] += s1, q[2] += s2;                                                           \
  }

/* Assignment step (clustering.h step c, codecs/lpca/assign.h): projections of groups of 8
   texels onto their candidate clusters' mean and eigen-BRDFs,
     P[(p * 8 + i) * V + j] (+)= sum_{r0 <= r < r0 + rc} X[texels[8 g + i]][r] Wt[k][j][r]
   for every pair p of group g (cand_off[g] <= p < cand_off[g + 1], k = cand[p]) and j < V.
   Wt holds each cluster's V vectors (c + 1 padded with zero vectors to a multiple of 3) as
   contiguous rows of d values; X is texel-major. Lanes run along the directions: a work-item
   keeps 8 texels x 3 vectors of float16 partial dot products in registers, so 11 loads feed 24
   FMAs and no lane is padding; the host runs one launch per chunk of rc directions, so a group's
   8 texel chunks stay in L1 across its candidates and the clusters' chunks in L2. */
__kernel void lpca_project(__global const float* X, int d, __global const uint* texels, __global const uint* cand_off,
                           __global const uint* cand, __global const float* Wt, int V, int r0, int rc, int groups, int first,
                           __global float* P) {
  int g = get_global_id(0);
  if (g >= groups) return;
  __global const uint* tx = texels + (size_t)g * 8;
  __global const float* x0 = X + (size_t)tx[0] * d + r0;
  __global const float* x1 = X + (size_t)tx[1] * d + r0;
  __global const float* x2 = X + (size_t)tx[2] * d + r0;
  __global const float* x3 = X + (size_t)tx[3] * d + r0;
  __global const float* x4 = X + (size_t)tx[4] * d + r0;
  __global const float* x5 = X + (size_t)tx[5] * d + r0;
  __global const float* x6 = X + (size_t)tx[6] * d + r0;
  __global const float* x7 = X + (size_t)tx[7] * d + r0;
  int r16 = rc & ~15;
  for (uint p = cand_off[g]; p < cand_off[g + 1]; ++p) {
    __global float* o = P + (size_t)p * 8 * V;
    for (int j = 0; j < V; j += 3) {
      __global const float* w0 = Wt + ((size_t)cand[p] * V + j) * d + r0;
      __global const float* w1 = w0 + d;
      __global const float* w2 = w1 + d;
      float16 z = (float16)(0.0f), x;
      float16 a00 = z, a01 = z, a02 = z, a10 = z, a11 = z, a12 = z, a20 = z, a21 = z, a22 = z, a30 = z, a31 = z, a32 = z;
      float16 a40 = z, a41 = z, a42 = z, a50 = z, a51 = z, a52 = z, a60 = z, a61 = z, a62 = z, a70 = z, a71 = z, a72 = z;
      for (int r = 0; r < r16; r += 16) {
        float16 v0 = vload16(0, w0 + r), v1 = vload16(0, w1 + r), v2 = vload16(0, w2 + r);
        LPCA_ROW(0, x0) LPCA_ROW(1, x1) LPCA_ROW(2, x2) LPCA_ROW(3, x3)
        LPCA_ROW(4, x4) LPCA_ROW(5, x5) LPCA_ROW(6, x6) LPCA_ROW(7, x7)
      }
      LPCA_STORE(0, x0) LPCA_STORE(1, x1) LPCA_STORE(2, x2) LPCA_STORE(3, x3)
      LPCA_STORE(4, x4) LPCA_STORE(5, x5) LPCA_STORE(6, x6) LPCA_STORE(7, x7)
    }
  }
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
