/* lpyr kernels: the Laplacian pyramid operators (codecs/lpyr/lpyr_cl.h is the host side; the
   C++ references are reduce / subtract_up in codecs/lpyr/pyramid.cpp, see lpyr_internal.h).
   Stacks are texel-major: d floats per texel (one per (light, view) image), texel x + w y.
   The host tiles a level by rows (buffers wrap row ranges of the caller's arrays), so each
   kernel gets the row offset of its input tile. A work-item handles one texel's whole vector in float16 steps: straight, memory-bound loops. */

/* F_{k+1}(i, j) = box3(F_k)(2i, 2j), clamped borders: output rows [y0, y0 + rows) of a level of
   size w x h; src holds input rows from ys0 on. The 9 taps are summed in (dy, dx) order and
   scaled by 1/9 at the end, as the reference does. One work-item per output texel. */
__kernel void lpyr_reduce(__global const float* src, int ys0, int w, int h, int d, __global float* dst, int y0, int rows) {
  int t = get_global_id(0);
  int w2 = (w + 1) / 2;
  if (t >= rows * w2) return;
  int cx = 2 * (t % w2), cy = 2 * (y0 + t / w2);
  __global const float* s[9];
  for (int dy = -1, i = 0; dy <= 1; ++dy)
    for (int dx = -1; dx <= 1; ++dx, ++i)
      s[i] = src + ((size_t)clamp(cx + dx, 0, w - 1) + (size_t)w * (clamp(cy + dy, 0, h - 1) - ys0)) * d;
  __global float* o = dst + (size_t)t * d;
  int r = 0;
  for (; r + 16 <= d; r += 16) {
    float16 acc = vload16(0, s[0] + r);
    for (int i = 1; i < 9; ++i) acc += vload16(0, s[i] + r);
    vstore16(acc * (1.0f / 9.0f), 0, o + r);
  }
  for (; r < d; ++r) {
    float acc = s[0][r];
    for (int i = 1; i < 9; ++i) acc += s[i][r];
    o[r] = acc * (1.0f / 9.0f);
  }
}

/* F_k(x, y) -= F_{k+1}(x / 2, y / 2) (nearest-neighbour up-sampling) for rows [y0, y0 + rows)
   of f (y0 even); next holds rows of level k + 1 from yn0 on. One work-item per parent texel:
   its vector is loaded once and subtracted from its (up to) 2 x 2 children, so the parent level
   is read once instead of four times (the kernel is memory-bound). */
__kernel void lpyr_subtract_up(__global float* f, int w, int d, int y0, int rows, __global const float* next, int yn0) {
  int t = get_global_id(0);
  int w2 = (w + 1) / 2, rows2 = (rows + 1) / 2;
  if (t >= rows2 * w2) return;
  int px = t % w2, py = t / w2;
  int nx = min(2, w - 2 * px), ny = min(2, rows - 2 * py);
  __global const float* s = next + ((size_t)px + (size_t)w2 * (y0 / 2 + py - yn0)) * d;
  __global float* o = f + ((size_t)(2 * px) + (size_t)w * (2 * py)) * d;
  size_t right = (size_t)d, down = (size_t)w * d;
  int r = 0;
  for (; r + 16 <= d; r += 16) {
    float16 p = vload16(0, s + r);
    vstore16(vload16(0, o + r) - p, 0, o + r);
    if (nx > 1) vstore16(vload16(0, o + right + r) - p, 0, o + right + r);
    if (ny > 1) {
      vstore16(vload16(0, o + down + r) - p, 0, o + down + r);
      if (nx > 1) vstore16(vload16(0, o + down + right + r) - p, 0, o + down + right + r);
    }
  }
  for (; r < d; ++r) {
    float p = s[r];
    o[r] -= p;
    if (nx > 1) o[right + r] -= p;
    if (ny > 1) {
      o[down + r] -= p;
      if (nx > 1) o[down + right + r] -= p;
    }
  }
}
