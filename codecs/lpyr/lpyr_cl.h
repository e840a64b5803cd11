// lpyr on OpenCL: the Laplacian pyramid operators reduce and subtract_up (lpyr_internal.h) as
// kernels (kernels/lpyr.cl). The C++ references are reduce / subtract_up themselves; the
// kernels compute the same sums in the same order, so results agree to float rounding.
// Levels larger than the device's allocation limit are processed in row tiles of <= 256 MiB
// whose buffers wrap the caller's arrays (no copies on a CPU device such as PoCL).
#pragma once
#include <cstddef>

#include "core/status.h"

namespace btfc::lpyr {

Status reduce_cl(const float* src, int w, int h, size_t d, float* dst);
Status subtract_up_cl(float* f, int w, int h, size_t d, const float* next);
// The kernels when OpenCL is in use (falling back under --device auto), else the references.
Status reduce_any(const float* src, int w, int h, size_t d, float* dst);
Status subtract_up_any(float* f, int w, int h, size_t d, const float* next);

}  // namespace btfc::lpyr
