/* mlvq kernels (codecs/mlvq/mlvq_cl.h is the host side; its *_reference functions are the C++
   truth). CPU-style for PoCL (toolchain.md 3): one work-item per candidate / pixel / query,
   straight loops, no local memory, no barriers. */

/* SSIM (one global window) of x against s e from moments over n values; s = the non-negative
   least-squares scale when `scaled`, else 1. C1 = (0.01 L)^2, C2 = (0.03 L)^2. */
inline float mlvq_ssim(float n, float sx, float sxx, float se, float see, float sxe, float L, int scaled, float* scale) {
  float s = 1.0f;
  if (scaled) s = see > 0.0f ? fmax(0.0f, sxe / see) : 0.0f;
  *scale = s;
  float mx = sx / n, me = se / n, my = s * me;
  float vx = fmax(0.0f, sxx / n - mx * mx), vy = fmax(0.0f, s * s * (see / n - me * me));
  float cxy = s * (sxe / n - mx * me);
  float c1 = (0.01f * L) * (0.01f * L), c2 = (0.03f * L) * (0.03f * L);
  if (c1 == 0.0f && c2 == 0.0f) return 1.0f;
  return ((2.0f * mx * my + c1) * (2.0f * cxy + c2)) / ((mx * mx + my * my + c1) * (vx + vy + c2));
}

inline float mlvq_dot(__global const float* a, __global const float* b, int n) {
  float8 acc = (float8)(0.0f);
  int k = 0;
  for (; k + 8 <= n; k += 8) acc = mad(vload8(0, a + k), vload8(0, b + k), acc);
  float4 h = acc.lo + acc.hi;
  float s = (h.x + h.y) + (h.z + h.w);
  for (; k < n; ++k) s = mad(a[k], b[k], s);
  return s;
}

/* xm: 5 floats per candidate (sum x, sum x^2, peak, sum xc, sum xc^2); em: 4 per entry. The score
   is the margin over the thresholds: min(lum SSIM - tl, chroma SSIM - tc) over the parts present. */
__kernel void mlvq_ssim_search(__global const float* Xl, __global const float* Xc, __global const float* El,
                               __global const float* Ec, __global const float* xm, __global const float* em, int B, int K,
                               int dl, int dc, float tl, float tc, __global int* best, __global float* best_sim, __global float* best_scale) {
  int i = get_global_id(0);
  if (i >= B) return;
  __global const float* m = xm + 5 * i;
  float bs = -3.0f, bsc = 1.0f;
  int bj = -1;
  for (int j = 0; j < K; ++j) {
    __global const float* e = em + 4 * j;
    float s = 2.0f, sc = 1.0f, unused;
    if (dl > 0) s = mlvq_ssim((float)dl, m[0], m[1], e[0], e[1], mlvq_dot(Xl + (size_t)i * dl, El + (size_t)j * dl, dl), m[2], 1, &sc) - tl;
    if (dc > 0 && s > bs)
      s = fmin(s, mlvq_ssim((float)dc, m[3], m[4], e[2], e[3], mlvq_dot(Xc + (size_t)i * dc, Ec + (size_t)j * dc, dc), 1.0f, 0, &unused) - tc);
    if (s > bs) {
      bs = s;
      bj = j;
      bsc = sc;
    }
  }
  best[i] = bj;
  best_sim[i] = bs;
  best_scale[i] = bsc;
}

/* RGB -> (L, r, g): L = (R+G+B)/3, (r, g) = (R, G)/(R+G+B), (1/3, 1/3) for black; negatives clamped. */
__kernel void mlvq_rgb_to_lrg(__global const float* rgb, int n, __global float* lrg) {
  int i = get_global_id(0);
  if (i >= n) return;
  float r = fmax(rgb[3 * i], 0.0f), g = fmax(rgb[3 * i + 1], 0.0f), b = fmax(rgb[3 * i + 2], 0.0f);
  float s = r + g + b;
  lrg[3 * i] = s * (1.0f / 3.0f);
  lrg[3 * i + 1] = s > 0.0f ? r / s : 1.0f / 3.0f;
  lrg[3 * i + 2] = s > 0.0f ? g / s : 1.0f / 3.0f;
}

/* One node of a texel by chained lookups (meta layout: mlvq_cl.h FlatModel). */
inline float3 mlvq_node(__global const int* meta, __global const uint* idx, __global const float* val, int texel, const int* coord) {
  int s = meta[0];
  uint e = idx[meta[20] + texel];
  float sc = val[meta[20] + texel];
  for (int k = 4; k > s; --k) {
    int o = meta[5 + k - 1] + (int)e * meta[k] + coord[k];
    sc *= val[o];
    e = idx[o];
  }
  uint li = idx[meta[17] + 2 * (int)e], ci = idx[meta[17] + 2 * (int)e + 1];
  for (int k = s; k > 1; --k) {
    int o = meta[9 + k - 1] + (int)li * meta[k] + coord[k];
    sc *= val[o];
    li = idx[o];
    ci = idx[meta[13 + k - 1] + (int)ci * meta[k] + coord[k]];
  }
  int nb = meta[1];
  float L = sc * val[meta[18] + (int)li * nb + coord[1]];
  float r = val[meta[19] + 2 * ((int)ci * nb + coord[1])], g = val[meta[19] + 2 * ((int)ci * nb + coord[1]) + 1];
  float S = 3.0f * L;
  return (float3)(S * r, S * g, S * (1.0f - r - g));
}

/* Batched evaluation: 4D multilinear interpolation over the 16 nodes around (phi, theta, alpha,
   beta), blended in RGB; phi is periodic, the other axes are clamped. */
__kernel void mlvq_eval(__global const int* meta, __global const uint* idx, __global const float* val,
                        __global const int* texel, __global const float4* coord, int n, __global float* out) {
  int q = get_global_id(0);
  if (q >= n) return;
  float4 c = coord[q];
  float v[4] = {c.w, c.z, c.y, c.x}; /* beta, alpha, theta, phi */
  int i0[4], i1[4];
  float w0[4], w1[4];
  for (int a = 0; a < 4; ++a) {
    int nn = meta[a + 1];
    if (nn == 1) {
      i0[a] = i1[a] = 0;
      w0[a] = 1.0f;
      w1[a] = 0.0f;
      continue;
    }
    float f = floor(v[a]);
    int k = (int)f;
    float t = v[a] - f;
    if (a == 3) {
      k = ((k % nn) + nn) % nn;
      i0[a] = k;
      i1[a] = (k + 1) % nn;
    } else {
      if (k >= nn - 1) { k = nn - 2; t = 1.0f; }
      if (k < 0) { k = 0; t = 0.0f; }
      i0[a] = k;
      i1[a] = k + 1;
    }
    w0[a] = 1.0f - t;
    w1[a] = t;
  }
  float3 acc = (float3)(0.0f);
  int tx = texel[q];
  for (int m = 0; m < 16; ++m) {
    float w = ((m & 1) ? w1[0] : w0[0]) * ((m & 2) ? w1[1] : w0[1]) * ((m & 4) ? w1[2] : w0[2]) * ((m & 8) ? w1[3] : w0[3]);
    if (w == 0.0f) continue;
    int coord4[5] = {0, (m & 1) ? i1[0] : i0[0], (m & 2) ? i1[1] : i0[1], (m & 4) ? i1[2] : i0[2], (m & 8) ? i1[3] : i0[3]};
    acc += w * mlvq_node(meta, idx, val, tx, coord4);
  }
  vstore3(acc, q, out);
}
