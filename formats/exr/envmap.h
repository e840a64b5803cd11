// Environment maps and rendered images as float RGB EXR files: the lat-long lighting that lpca
// relighting and `btfc bench --env` project (codecs/lpca/lpca.h project_latlong), and the images
// `btfc relight` / `btfc render` write. Only OpenEXR (no OpenImageIO): cheap to link.
#pragma once
#include <string>
#include <vector>

#include "core/sh.h"
#include "core/status.h"

namespace btfc {

// Writes an RGB float image (row-major, 3 floats per pixel) as a float EXR, atomically
// (temporary name + rename). Errors name the file.
Status write_rgb_exr(const std::string& path, int w, int h, const std::vector<float>& rgb);
// Reads an EXR's R, G, B channels (or Y, replicated to all three) as row-major RGB floats.
// Errors (missing file, bad data window, no colour channels) name the file.
Result<std::vector<float>> read_rgb_exr(const std::string& path, int& w, int& h);
// A lat-long EXR environment (layout: core/sh.h project_latlong) projected onto SH of `order`.
// Errors name the file.
Result<EnvironmentSH> read_environment(const std::string& path, int order);

}  // namespace btfc
