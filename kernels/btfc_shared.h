/* Shared between C++ and OpenCL C: plain structs and constants, so both sides agree on layouts.
   In OpenCL this file is prepended to every program's source; in C++ it is included. */
#ifndef BTFC_SHARED_H
#define BTFC_SHARED_H

#ifdef __OPENCL_VERSION__
typedef int btfc_i32;
typedef float btfc_f32;
#else
#include <cstdint>
typedef int32_t btfc_i32;
typedef float btfc_f32;
#endif

/* One interpolated fmf query: texel, and 3 light + 3 view (index, barycentric weight) pairs
   from core/interp.h (weights sum to 1; an exact measured direction has weights 1, 0, 0). */
typedef struct {
  btfc_i32 texel;
  btfc_i32 light[3];
  btfc_i32 view[3];
  btfc_f32 wl[3];
  btfc_f32 wv[3];
} btfc_fmf_query;

/* fmf colour modes (codecs/fmf/fmf.h): rgb = one block, colour in the rows; dfmf = three
   blocks Y' (log), U/Y, V/Y per (light, view) row. */
#define BTFC_FMF_RGB 0
#define BTFC_FMF_DFMF 1
#define BTFC_DRR_EPS 1e-5f

#ifndef __OPENCL_VERSION__
static_assert(sizeof(btfc_fmf_query) == 52, "btfc_fmf_query layout is shared with OpenCL C");
#endif

#endif
