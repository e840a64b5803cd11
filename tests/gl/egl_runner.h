// A headless OpenGL ES harness for exported shaders: runs an export directory's btf.frag on a
// real GL implementation (Mesa's llvmpipe through surfaceless EGL, toolchain.md section 7) and
// reads the results back, so tests compare what a GPU computes with the exporter's CPU
// emulation and with the model.
//
// Generic by construction: everything comes from the directory, through the pinned shader
// contract of formats/gpu/export.h (manifest.json + *.ktx2 + btf.frag), so every codec's
// exporter runs here without changes:
//   - textures are read from the .ktx2 files with gpu::read_ktx2 (the files, not an in-memory
//     bundle, are what is tested), checked against the manifest (format, size, layers, levels)
//     and uploaded with all mip levels: texture unit i = the manifest's i-th texture, 2D or 2D
//     array, the GL internal format of gpu::format_info; integer formats as *_INTEGER with
//     NEAREST filters, float / unorm formats with the manifest's filter (nearest | linear,
//     linear = trilinear over the mip chain; RGBA32F linear needs GL_OES_texture_float_linear);
//   - btf.frag gets `#define BTFC_NO_MAIN` after its `#version 300 es` line and a harness
//     main() that reads one query per fragment from three RGBA32F textures
//       q0 = (u, v, light, view)   q1 = (wl, 0)   q2 = (wv, 0)
//     and calls btf_eval_measured(uv, light, view) when light >= 0, else btf_eval(uv, wl, wv);
//   - the result goes to an RGBA32F colour attachment and comes back with glReadPixels.
// Every active sampler of the linked program must be a manifest texture (or the harness's) of
// the matching kind (float / unsigned integer, 2D / 2D array): a sampler the manifest does not
// list would silently read unit 0.
#pragma once
#include <span>
#include <string>
#include <vector>

#include "core/status.h"
#include "formats/gpu/export.h"

namespace btfc::gltest {

// Creates (once per process) a surfaceless EGL display and a GLES 3.2 (else 3.0) context and
// makes it current. Not ok = why GL cannot run here (tests skip with this message).
Status gl_context();
// "OpenGL ES 3.2 Mesa 22.3.6, llvmpipe (LLVM 15.0.6, 256 bits)" of the context.
std::string gl_description();

// Evaluates the export in `export_dir` at the queries: 3 floats (r, g, b) per query, in order.
// Errors name the file or GL stage (shader compile / link logs included).
Result<std::vector<float>> gl_eval(const std::string& export_dir, std::span<const gpu::ShaderQuery> queries);

}  // namespace btfc::gltest
