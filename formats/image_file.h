// Image files (PNG, JPEG, EXR, TIFF, ...): what image sets and previews read and write, through
// OpenImageIO in a plugin (formats/imageio/) that is loaded the first time a process needs it.
// A process that never touches an image file never maps OpenImageIO and its dependencies (FFmpeg,
// OpenCV, ...; 133 MB of resident memory and 0.36 s at start when linked, docs/benchmarks.md).
//
// The plugin, libbtfc_imageio.so, is looked for in this order: $BTFC_IMAGEIO_PLUGIN; the path a
// program built against the installed package carries (btfcConfig.cmake); beside the binary
// holding this code, its parent folder, <binary>/../lib/btfc and <binary>/../../btfc
// (a build tree: build/btfc, build/tests/, build/python/; an install: bin/btfc,
// lib/python3/dist-packages/); the configured install path; the build tree's path. When none
// loads, every image call fails with one error that says what was tried.
// Errors name the path.
#pragma once
#include <cstdint>
#include <string>

#include "core/status.h"

namespace btfc::image_file {

struct Info {
  int width = 0, height = 0, depth = 1, channels = 0;
  bool is_uint8 = false;  // info(): the file stores 8-bit integers; read_rgb(): u8 was filled
  bool size_ok = true;    // read_rgb(): false when the file is not want_w x want_h (nothing read)
};

Result<Info> info(const std::string& path);
// Channels 0..2 (row 0 at the top, one thread): 8-bit into u8 (width x height x 3) when u8 is not
// null and the file is 8-bit, else float into f32 (integer files normalized to [0, 1]). A file
// of another size than want_w x want_h (when > 0) returns size_ok = false and reads nothing; a
// file of fewer than 3 channels reads nothing (Info says how many).
Result<Info> read_rgb(const std::string& path, int want_w, int want_h, uint8_t* u8, float* f32);
enum class FileType { srgb8, half, float32 };
// Writes width x height RGB pixels (u8 or float, one of them) as `type` (format from the
// extension; `shown` is the name errors use, e.g. the final path of a temporary file).
Status write_rgb(const std::string& path, const std::string& shown, int width, int height, const uint8_t* u8, const float* f32,
                 FileType type);
// Whether this process has loaded the plugin (tests: a bare process must not).
bool loaded();
// The plugin's file (loading it if not yet loaded), or "" when it cannot be loaded.
std::string plugin_path();

}  // namespace btfc::image_file
