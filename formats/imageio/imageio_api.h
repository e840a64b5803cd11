// The image-file plugin's table (libbtfc_imageio.so, formats/imageio/imageio_plugin.cpp): the
// few OpenImageIO calls btfc makes, behind a C table so that OpenImageIO is loaded only by a
// process that reads or writes an image file (formats/image_file.h dlopen()s the plugin).
// Linking OpenImageIO into every process cost 133 MB of resident memory and 0.36 s at start
// (its dependencies' relocations and initializers), before any work (docs/benchmarks.md).
//
// Plain C types only: the plugin and btfc are built together, but a table of C functions keeps
// the boundary free of C++ ABI questions. Every function returns 0 on success, else a code
// below with a message (no path: the caller names the file) in err[0, err_size).
#pragma once
#include <cstddef>

extern "C" {

enum {
  BTFC_IMAGEIO_API_VERSION = 1,
  BTFC_IMAGEIO_OK = 0,
  BTFC_IMAGEIO_CANNOT_OPEN = 1,  // no reader / writer, or the file cannot be opened
  BTFC_IMAGEIO_SIZE = 2,         // read_rgb: not want_w x want_h (info filled, nothing read)
  BTFC_IMAGEIO_FAILED = 3,       // reading, writing or closing failed
};

struct BtfcImageInfo {
  int width, height, depth, channels;
  int is_uint8;  // the file stores 8-bit integers
};

struct BtfcImageApi {
  int version;  // BTFC_IMAGEIO_API_VERSION
  // The size and channel count of the first subimage.
  int (*info)(const char* path, BtfcImageInfo* info, char* err, size_t err_size);
  // Channels 0..2 of the first subimage, row 0 at the top, one thread (callers read files in
  // parallel): as 8-bit into u8 when u8 is not null and the file is 8-bit, else as float into f32
  // (integer files normalized to [0, 1]). Straight (unassociated) alpha: colour is never
  // premultiplied. want_w / want_h > 0: another size returns BTFC_IMAGEIO_SIZE before reading.
  int (*read_rgb)(const char* path, int want_w, int want_h, unsigned char* u8, float* f32, BtfcImageInfo* info, char* err,
                  size_t err_size);
  // Writes w x h RGB pixels (8-bit when in_u8, else float) as 8-bit sRGB-tagged (file_type 0),
  // half (1) or float (2); the format follows the path's extension. One thread.
  int (*write_rgb)(const char* path, int w, int h, const void* pixels, int in_u8, int file_type, char* err, size_t err_size);
};

// The plugin's one exported symbol.
const BtfcImageApi* btfc_imageio_api(void);
}
