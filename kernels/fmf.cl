/* fmf kernels (codecs/fmf/fmf_cl.h is the host side, its *_reference functions the C++ truth).

   Factors layout (padded to one component count C for all blocks):
     U   [blocks][rows_per_block][C]   rgb: 1 block, row = c + 3 (l + nL v); dfmf: 3 blocks Y', U/Y, V/Y, row = l + nL v
     SxV [blocks][texels][C]
   Written CPU-style for PoCL (toolchain.md 3): one work-item per query or per 16-row strip of a
   texel, straight loops, float16 vectors, no local memory and no barriers. */

/* Dot product over the C components: 8 lanes of partial sums (a float8 FMA per step) rather
   than one serial FMA chain, whose latency would bound the throughput on a CPU. The C++
   reference sums in the same order. */
inline float fmf_dot(__global const float* a, __global const float* b, int C) {
  float8 acc = (float8)(0.0f);
  int k = 0;
  for (; k + 8 <= C; k += 8) acc = mad(vload8(0, a + k), vload8(0, b + k), acc);
  float4 h = acc.lo + acc.hi;
  float s = (h.x + h.y) + (h.z + h.w);
  for (; k < C; ++k) s = mad(a[k], b[k], s);
  return s;
}

/* The three colour rows u, u + C, u + 2C dotted with one texel row s: s is loaded once, three
   independent 8-lane sums in fmf_dot's order (so results equal the references'). */
inline float3 fmf_dot3(__global const float* u, __global const float* s, int C) {
  float8 a0 = (float8)(0.0f), a1 = a0, a2 = a0;
  int k = 0;
  for (; k + 8 <= C; k += 8) {
    float8 x = vload8(0, s + k);
    a0 = mad(vload8(0, u + k), x, a0);
    a1 = mad(vload8(0, u + C + k), x, a1);
    a2 = mad(vload8(0, u + 2 * C + k), x, a2);
  }
  float4 h0 = a0.lo + a0.hi, h1 = a1.lo + a1.hi, h2 = a2.lo + a2.hi;
  float3 r = (float3)((h0.x + h0.y) + (h0.z + h0.w), (h1.x + h1.y) + (h1.z + h1.w), (h2.x + h2.y) + (h2.z + h2.w));
  for (; k < C; ++k) r = mad((float3)(u[k], u[C + k], u[2 * C + k]), (float3)(s[k]), r);
  return r;
}

/* The DFMF colour inverse: Y = exp(Y') - eps, U = U' (Y + eps), V = V' (Y + eps), then YUV -> RGB.
   eps is the model's luminance offset (Bonn's colour model 11: BTFC_DRR_EPS; btfc's default
   comes from the data). */
inline float3 fmf_undecorrelate(float ylog, float u, float v, float eps) {
  float y = exp(ylog) - eps;
  float s = y + eps;
  u *= s;
  v *= s;
  return (float3)(y + 1.13983f * v, y - 0.39465f * u - 0.5806f * v, y + 2.03211f * u);
}

/* One measured value. dfmf: each block's dot stops at its own component count (Cy, Cu, Cv <= C;
   the chroma blocks' columns past theirs are zero padding to the luminance's C, often hundreds
   where the chroma has a few), so only the rounding of the sums differs from the reference's
   padded dots. rgb ignores them. */
inline float3 fmf_value(__global const float* U, __global const float* SxV, int C, int nL, int rows_per_block,
                        int texels, int mode, float eps, int Cy, int Cu, int Cv, int texel, int l, int v) {
  if (mode == BTFC_FMF_RGB) {
    return fmf_dot3(U + (size_t)(3 * (l + nL * v)) * C, SxV + (size_t)texel * C, C);
  }
  size_t r = (size_t)(l + nL * v) * C, t = (size_t)texel * C;
  size_t ub = (size_t)rows_per_block * C, sb = (size_t)texels * C;
  return fmf_undecorrelate(fmf_dot(U + r, SxV + t, Cy), fmf_dot(U + ub + r, SxV + sb + t, Cu),
                           fmf_dot(U + 2 * ub + r, SxV + 2 * sb + t, Cv), eps);
}

/* Evaluation at measured (texel, light, view) triples: q[i] = (texel, light, view, unused). */
__kernel void fmf_eval_measured(__global const float* U, __global const float* SxV, int C, int nL, int rows_per_block,
                                int texels, int mode, float eps, int Cy, int Cu, int Cv, __global const int4* q, int n,
                                __global float* out) {
  int i = get_global_id(0);
  if (i >= n) return;
  int4 Q = q[i];
  float3 rgb = fmf_value(U, SxV, C, nL, rows_per_block, texels, mode, eps, Cy, Cu, Cv, Q.x, Q.y, Q.z);
  vstore3(rgb, i, out);
}

/* Interpolated evaluation: 3 x 3 = 9 measured values blended with the barycentric weights of
   the light and view triangles (seed 000 section 4); interpolation in linear RGB.
   rgb mode is linear in U, so sum_ab w_ab (U_ab . s) = (sum_ab w_ab U_ab) . s: the 9 rows are
   blended 8 components at a time and dotted with the texel's row as they go, which keeps one
   horizontal reduction per channel instead of 27 (the reduction dominated at rank 32).
   dfmf is not linear (exp per sample), so it keeps the 9 separate values. */
__kernel void fmf_eval_interp(__global const float* U, __global const float* SxV, int C, int nL, int rows_per_block,
                              int texels, int mode, float eps, int Cy, int Cu, int Cv, __global const btfc_fmf_query* q,
                              int n, __global float* out) {
  int i = get_global_id(0);
  if (i >= n) return;
  btfc_fmf_query Q = q[i];
  if (mode == BTFC_FMF_RGB) {
    __global const float* s = SxV + (size_t)Q.texel * C;
    __global const float* row[9];
    float w[9];
    int m = 0;
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) {
        float wab = Q.wl[a] * Q.wv[b];
        if (wab == 0.0f) continue;
        row[m] = U + (size_t)(3 * (Q.light[a] + nL * Q.view[b])) * C;
        w[m++] = wab;
      }
    float8 a0 = (float8)(0.0f), a1 = a0, a2 = a0;
    int k = 0;
    for (; k + 8 <= C; k += 8) {
      float8 u0 = (float8)(0.0f), u1 = u0, u2 = u0;
      for (int j = 0; j < m; ++j) {
        u0 = mad((float8)(w[j]), vload8(0, row[j] + k), u0);
        u1 = mad((float8)(w[j]), vload8(0, row[j] + C + k), u1);
        u2 = mad((float8)(w[j]), vload8(0, row[j] + 2 * C + k), u2);
      }
      float8 x = vload8(0, s + k);
      a0 = mad(u0, x, a0);
      a1 = mad(u1, x, a1);
      a2 = mad(u2, x, a2);
    }
    float4 h0 = a0.lo + a0.hi, h1 = a1.lo + a1.hi, h2 = a2.lo + a2.hi;
    float3 r = (float3)((h0.x + h0.y) + (h0.z + h0.w), (h1.x + h1.y) + (h1.z + h1.w), (h2.x + h2.y) + (h2.z + h2.w));
    for (; k < C; ++k) {
      float u0 = 0.0f, u1 = 0.0f, u2 = 0.0f;
      for (int j = 0; j < m; ++j) {
        u0 = mad(w[j], row[j][k], u0);
        u1 = mad(w[j], row[j][C + k], u1);
        u2 = mad(w[j], row[j][2 * C + k], u2);
      }
      r = mad((float3)(u0, u1, u2), (float3)(s[k]), r);
    }
    vstore3(r, i, out);
    return;
  }
  float3 acc = (float3)(0.0f);
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) {
      float w = Q.wl[a] * Q.wv[b];
      if (w != 0.0f) acc += w * fmf_value(U, SxV, C, nL, rows_per_block, texels, mode, eps, Cy, Cu, Cv, Q.texel, Q.light[a],
                                    Q.view[b]);
    }
  vstore3(acc, i, out);
}

/* a[j] = sum over k < Ck of S[j C + k] Ut[k][d0 .. d0 + 15] (row stride `dirs`), j = 0..3: a strip
   of 16 columns of Ut for 4 consecutive rows of S, each Ut load feeding the 4 (both decodes). */
inline void fmf_strip4(__global const float* Ut, __global const float* S, int C, int Ck, int dirs, int d0, float16* a) {
  float16 a0 = (float16)(0.0f), a1 = a0, a2 = a0, a3 = a0;
  for (int k = 0; k < Ck; ++k) {
    float16 u = vload16(0, Ut + (size_t)k * dirs + d0);
    a0 = mad((float16)(S[k]), u, a0);
    a1 = mad((float16)(S[C + k]), u, a1);
    a2 = mad((float16)(S[2 * C + k]), u, a2);
    a3 = mad((float16)(S[3 * C + k]), u, a3);
  }
  a[0] = a0, a[1] = a1, a[2] = a2, a[3] = a3;
}

/* Decode, rgb mode: out[t][r] = sum_k SX[t][k] Ut[k][r] for a texel block.
   Ut is the selected U rows transposed (C x rows), so 16 consecutive rows load as one float16.
   Work-item (strip, tb) computes rows [16 strip, 16 strip + 16) of texels 4 tb .. 4 tb + 3: each
   Ut load feeds 4 texels (register blocking, toolchain.md 3c). */
__kernel void fmf_decode_rgb(__global const float* Ut, __global const float* SX, int C, int rows, int n, __global float* out) {
  int r0 = get_global_id(0) * 16, t0 = get_global_id(1) * 4;
  if (t0 >= n || r0 >= rows) return;
  int nt = min(4, n - t0);
  if (r0 + 16 <= rows && nt == 4) {
    float16 a[4];
    fmf_strip4(Ut, SX + (size_t)t0 * C, C, C, rows, r0, a);
    for (int j = 0; j < 4; ++j) vstore16(a[j], 0, out + (size_t)(t0 + j) * rows + r0);
    return;
  }
  int rend = min(r0 + 16, rows);
  for (int t = t0; t < t0 + nt; ++t)
    for (int r = r0; r < rend; ++r) {
      float s = 0.0f;
      for (int k = 0; k < C; ++k) s = mad(SX[(size_t)t * C + k], Ut[(size_t)k * rows + r], s);
      out[(size_t)t * rows + r] = s;
    }
}

/* Decode, dfmf mode: Ut holds 3 blocks (C x dirs each), SX 3 blocks (n x C each); output is
   RGB interleaved per (light, view) row: out[t][3 d + c]. Block c has Cb[c] <= C components
   (the rest zero padding: dfmf's chroma ranks are often a few where the luminance has hundreds),
   so each block's sum stops at its own (adding the padding's zeros changed nothing but the time:
   3 x the operations at chroma rank 4 and luminance 1024). Work-item (strip of 16 dirs, texels
   4 tb .. 4 tb + 3): each Ut load feeds 4 texels, as fmf_decode_rgb (a work-item per texel took
   41 s for the textile at luminance rank 1024 on PoCL's CPU device, the C++ path 2.6 s). */
__kernel void fmf_decode_dfmf(__global const float* Ut, __global const float* SX, int C, int Cy, int Cu, int Cv, int dirs, int n,
                              float eps, __global float* out) {
  int d0 = get_global_id(0) * 16, t0 = get_global_id(1) * 4;
  if (t0 >= n || d0 >= dirs) return;
  size_t ub = (size_t)C * dirs, sb = (size_t)n * C;
  int nt = min(4, n - t0);
  if (d0 + 16 <= dirs && nt == 4) {
    float16 y[4], u[4], v[4];
    fmf_strip4(Ut, SX + (size_t)t0 * C, C, Cy, dirs, d0, y);
    fmf_strip4(Ut + ub, SX + sb + (size_t)t0 * C, C, Cu, dirs, d0, u);
    fmf_strip4(Ut + 2 * ub, SX + 2 * sb + (size_t)t0 * C, C, Cv, dirs, d0, v);
    for (int j = 0; j < 4; ++j) {
      float yy[16], uu[16], vv[16];
      vstore16(y[j], 0, yy);
      vstore16(u[j], 0, uu);
      vstore16(v[j], 0, vv);
      __global float* o = out + (size_t)(t0 + j) * dirs * 3;
      for (int i = 0; i < 16; ++i) vstore3(fmf_undecorrelate(yy[i], uu[i], vv[i], eps), d0 + i, o);
    }
    return;
  }
  int dend = min(d0 + 16, dirs);
  for (int t = t0; t < t0 + nt; ++t) {
    __global float* o = out + (size_t)t * dirs * 3;
    for (int d = d0; d < dend; ++d) {
      float y = 0.0f, u = 0.0f, v = 0.0f;
      for (int k = 0; k < Cy; ++k) y = mad(SX[(size_t)t * C + k], Ut[(size_t)k * dirs + d], y);
      for (int k = 0; k < Cu; ++k) u = mad(SX[sb + (size_t)t * C + k], Ut[ub + (size_t)k * dirs + d], u);
      for (int k = 0; k < Cv; ++k) v = mad(SX[2 * sb + (size_t)t * C + k], Ut[2 * ub + (size_t)k * dirs + d], v);
      vstore3(fmf_undecorrelate(y, u, v, eps), d, o);
    }
  }
}

/* One interpolated (light, view) direction pair and many texels, rgb mode: the renderer's case
   (a frame or tile of texels under one light and view). Ub is the pair's 9 eigen-ABRDF rows
   already blended (3 x C, once per pair on the host), so each texel costs one C-length dot per
   channel: the measured-direction cost, 9 x fewer operations than fmf_eval_interp. */
__kernel void fmf_eval_pair_rgb(__global const float* Ub, __global const float* SxV, int C, __global const int* texels,
                                int n, __global float* out) {
  int i = get_global_id(0);
  if (i >= n) return;
  vstore3(fmf_dot3(Ub, SxV + (size_t)texels[i] * C, C), i, out);
}
