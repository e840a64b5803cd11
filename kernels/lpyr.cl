/* lpyr kernels: the Laplacian pyramid operators (codecs/lpyr/lpyr_cl.h is the host side; the
   C++ references are reduce / subtract_up in codecs/lpyr/pyramid.cpp, see lpyr_internal.h).
   Stacks are texel-major: d floats per texel (one per (light, view) image), texel x + w y.
   The host tiles a level by rows (buffers wrap row ranges of the caller's arrays), so each
   kernel gets the row offset of its input tile. A work-item handles one output texel and a run
   of 64 consecutive values of its vector (4 float16): straight, memory-bound loops. */

#define LPYR_RUN 64

/* F_{k+1}(i, j) = box3(F_k)(2i, 2j), clamped borders: output rows [y0, y0 + rows) of a level of
   size w x h; src holds input rows from ys0 on. The 9 taps are summed in (dy, dx) order and
   scaled by 1/9 at the end, as the reference does. */
__kernel void lpyr_reduce(__global const float* src, int ys0, int w, int h, int d, __global float* dst, int y0, int rows) {
  int r0 = get_global_id(0) * LPYR_RUN, t = get_global_id(1);
  int w2 = (w + 1) / 2;
  if (r0 >= d || t >= rows * w2) return;
  int cx = 2 * (t % w2), cy = 2 * (y0 + t / w2);
  __global float* o = dst + (size_t)t * d;
  int rend = min(r0 + LPYR_RUN, d);
  int r = r0;
  for (; r + 16 <= rend; r += 16) {
    float16 acc = (float16)(0.0f);
    for (int dy = -1; dy <= 1; ++dy) {
      int yy = clamp(cy + dy, 0, h - 1) - ys0;
      for (int dx = -1; dx <= 1; ++dx) {
        int xx = clamp(cx + dx, 0, w - 1);
        acc += vload16(0, src + ((size_t)xx + (size_t)w * yy) * d + r);
      }
    }
    vstore16(acc * (1.0f / 9.0f), 0, o + r);
  }
  for (; r < rend; ++r) {
    float acc = 0.0f;
    for (int dy = -1; dy <= 1; ++dy) {
      int yy = clamp(cy + dy, 0, h - 1) - ys0;
      for (int dx = -1; dx <= 1; ++dx) acc += src[((size_t)clamp(cx + dx, 0, w - 1) + (size_t)w * yy) * d + r];
    }
    o[r] = acc * (1.0f / 9.0f);
  }
}

/* F_k(x, y) -= F_{k+1}(x / 2, y / 2) (nearest-neighbour up-sampling) for rows [y0, y0 + rows)
   of f; next holds rows of level k + 1 from yn0 on. */
__kernel void lpyr_subtract_up(__global float* f, int w, int d, int y0, int rows, __global const float* next, int yn0) {
  int r0 = get_global_id(0) * LPYR_RUN, t = get_global_id(1);
  if (r0 >= d || t >= rows * w) return;
  int x = t % w, y = y0 + t / w, w2 = (w + 1) / 2;
  __global float* o = f + (size_t)t * d;
  __global const float* s = next + ((size_t)(x / 2) + (size_t)w2 * (y / 2 - yn0)) * d;
  int rend = min(r0 + LPYR_RUN, d);
  int r = r0;
  for (; r + 16 <= rend; r += 16) vstore16(vload16(0, o + r) - vload16(0, s + r), 0, o + r);
  for (; r < rend; ++r) o[r] -= s[r];
}
