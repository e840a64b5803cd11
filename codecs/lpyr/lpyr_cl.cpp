// lpyr OpenCL host code; see lpyr_cl.h. The references are in pyramid.cpp.
#include "codecs/lpyr/lpyr_cl.h"

#include <algorithm>
#include <string>

#include "codecs/lpyr/lpyr_internal.h"
#include "core/cl_runtime.h"

namespace btfc::lpyr {
namespace {

constexpr size_t k_tile_bytes = size_t(256) << 20;

Status check_sizes(int w, int h, size_t d) {
  if (w <= 0 || h <= 0 || d == 0 || d > size_t(1) << 30 || size_t(w) * d * 4 * 3 > k_tile_bytes)
    return Status(StatusCode::device_error, "lpyr kernels: level " + std::to_string(w) + "x" + std::to_string(h) + " with " +
                                                std::to_string(d) + " values per texel does not fit a " +
                                                std::to_string(k_tile_bytes >> 20) + " MiB row tile");
  return {};
}

}  // namespace

Status reduce_cl(const float* src, int w, int h, size_t d, float* dst) {
  BTFC_RETURN_IF_ERROR(check_sizes(w, h, d));
  BTFC_ASSIGN_OR_RETURN(ocl::Runtime * rt, ocl::Runtime::get());
  BTFC_ASSIGN_OR_RETURN(ocl::Kernel k, rt->kernel("lpyr", "lpyr_reduce"));
  const int w2 = (w + 1) / 2, h2 = (h + 1) / 2;
  const size_t row_in = size_t(w) * d * 4;
  // Output rows per tile: the tile's 2 R + 1 input rows stay under k_tile_bytes.
  const int R = int(std::max<size_t>(1, (k_tile_bytes / row_in - 1) / 2));
  for (int y0 = 0; y0 < h2; y0 += R) {
    const int rows = std::min(R, h2 - y0);
    const int ys0 = std::max(0, 2 * y0 - 1), ys1 = std::min(h - 1, 2 * (y0 + rows - 1) + 1);
    BTFC_ASSIGN_OR_RETURN(ocl::Buffer sb, ocl::Buffer::wrap(*rt, size_t(ys1 - ys0 + 1) * row_in,
                                                            const_cast<float*>(src + size_t(ys0) * size_t(w) * d), ocl::Access::read_only));
    const size_t out_bytes = size_t(rows) * size_t(w2) * d * 4;
    float* o = dst + size_t(y0) * size_t(w2) * d;
    BTFC_ASSIGN_OR_RETURN(ocl::Buffer ob, ocl::Buffer::wrap(*rt, out_bytes, o, ocl::Access::write_only));
    BTFC_RETURN_IF_ERROR(k.args(sb, int32_t(ys0), int32_t(w), int32_t(h), int32_t(d), ob, int32_t(y0), int32_t(rows)));
    const size_t global = size_t(rows) * size_t(w2);
    BTFC_RETURN_IF_ERROR(k.launch(1, &global, nullptr, "lpyr_reduce"));
    BTFC_RETURN_IF_ERROR(ob.sync_to_host(out_bytes));
  }
  return {};
}

namespace {

// *done: rows of f finished (a multiple of 2 or h), so a fallback can finish the rest.
Status subtract_up_tiles(float* f, int w, int h, size_t d, const float* next, int* done) {
  *done = 0;
  BTFC_RETURN_IF_ERROR(check_sizes(w, h, d));
  BTFC_ASSIGN_OR_RETURN(ocl::Runtime * rt, ocl::Runtime::get());
  BTFC_ASSIGN_OR_RETURN(ocl::Kernel k, rt->kernel("lpyr", "lpyr_subtract_up"));
  const int w2 = (w + 1) / 2;
  const size_t row = size_t(w) * d * 4, row2 = size_t(w2) * d * 4;
  const int R = std::max(2, int(k_tile_bytes / (row + row2)) / 2 * 2);  // even: tiles start on even rows
  for (int y0 = 0; y0 < h; y0 += R) {
    const int rows = std::min(R, h - y0), yn0 = y0 / 2, yn1 = (y0 + rows - 1) / 2;
    const size_t f_bytes = size_t(rows) * row;
    BTFC_ASSIGN_OR_RETURN(ocl::Buffer fb, ocl::Buffer::wrap(*rt, f_bytes, f + size_t(y0) * size_t(w) * d, ocl::Access::read_write));
    BTFC_ASSIGN_OR_RETURN(ocl::Buffer nb, ocl::Buffer::wrap(*rt, size_t(yn1 - yn0 + 1) * row2,
                                                            const_cast<float*>(next + size_t(yn0) * size_t(w2) * d), ocl::Access::read_only));
    BTFC_RETURN_IF_ERROR(k.args(fb, int32_t(w), int32_t(d), int32_t(y0), int32_t(rows), nb, int32_t(yn0)));
    const size_t global = size_t((rows + 1) / 2) * size_t(w2);  // one work-item per parent texel
    BTFC_RETURN_IF_ERROR(k.launch(1, &global, nullptr, "lpyr_subtract_up"));
    BTFC_RETURN_IF_ERROR(fb.sync_to_host(f_bytes));
    *done = y0 + rows;
  }
  return {};
}

}  // namespace

Status subtract_up_cl(float* f, int w, int h, size_t d, const float* next) {
  int done = 0;
  return subtract_up_tiles(f, w, h, d, next, &done);
}

Status reduce_any(const float* src, int w, int h, size_t d, float* dst) {
  if (ocl::use_opencl()) {
    Status s = reduce_cl(src, w, h, d, dst);
    if (s.ok() || !ocl::fall_back_after(s)) return s;
  }
  reduce(src, w, h, d, dst);
  return {};
}

Status subtract_up_any(float* f, int w, int h, size_t d, const float* next) {
  int done = 0;
  if (ocl::use_opencl()) {
    Status s = subtract_up_tiles(f, w, h, d, next, &done);
    if (s.ok() || !ocl::fall_back_after(s)) return s;
  }
  // In place: rows the kernel finished must not be subtracted twice. `done` is even (or h), so
  // row y of the rest still has parent row y / 2 - done / 2 of the shifted next level.
  if (done < h) subtract_up(f + size_t(done) * size_t(w) * d, w, h - done, d, next + size_t(done / 2) * size_t((w + 1) / 2) * d);
  return {};
}

}  // namespace btfc::lpyr
