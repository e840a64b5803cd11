// libbtfc_imageio.so: btfc's OpenImageIO calls (the table of imageio_api.h), loaded on first use
// by formats/image_file.cpp. OIIO can throw (std::bad_alloc, fmt errors): every exception stops
// here and becomes an error code with its message.
#include <OpenImageIO/imageio.h>

#include <cstdio>
#include <exception>
#include <string>

#include "imageio_api.h"

namespace {

int fail(int code, const std::string& msg, char* err, size_t n) {
  if (err && n) std::snprintf(err, n, "%s", msg.c_str());
  return code;
}

void fill(const OIIO::ImageSpec& s, BtfcImageInfo* info) {
  info->width = s.width;
  info->height = s.height;
  info->depth = s.depth;
  info->channels = s.nchannels;
  info->is_uint8 = s.format == OIIO::TypeDesc::UINT8;
}

int info_impl(const char* path, BtfcImageInfo* info, char* err, size_t n) try {
  auto in = OIIO::ImageInput::open(path);
  if (!in) return fail(BTFC_IMAGEIO_CANNOT_OPEN, "cannot open image: " + OIIO::geterror(), err, n);
  fill(in->spec(), info);
  return BTFC_IMAGEIO_OK;
} catch (const std::exception& e) {
  return fail(BTFC_IMAGEIO_FAILED, std::string("OpenImageIO: ") + e.what(), err, n);
}

int read_impl(const char* path, int want_w, int want_h, unsigned char* u8, float* f32, BtfcImageInfo* info, char* err, size_t n) try {
  OIIO::ImageSpec config;
  config.attribute("oiio:UnassociatedAlpha", 1);  // PNG alpha must not premultiply the colour
  auto in = OIIO::ImageInput::open(path, &config);
  if (!in) return fail(BTFC_IMAGEIO_CANNOT_OPEN, "cannot open image: " + OIIO::geterror(), err, n);
  in->threads(1);  // parallelism is across files
  fill(in->spec(), info);
  if ((want_w > 0 && info->width != want_w) || (want_h > 0 && info->height != want_h) || info->depth > 1)
    return BTFC_IMAGEIO_SIZE;
  if (info->channels < 3) return BTFC_IMAGEIO_OK;  // the caller says what is missing
  const bool as_u8 = u8 && info->is_uint8;
  if (!in->read_image(0, 0, 0, 3, as_u8 ? OIIO::TypeDesc::UINT8 : OIIO::TypeDesc::FLOAT, as_u8 ? static_cast<void*>(u8) : f32))
    return fail(BTFC_IMAGEIO_FAILED, "cannot read pixels: " + in->geterror(), err, n);
  if (!as_u8) info->is_uint8 = 0;  // what was delivered
  return BTFC_IMAGEIO_OK;
} catch (const std::exception& e) {
  return fail(BTFC_IMAGEIO_FAILED, std::string("OpenImageIO: ") + e.what(), err, n);
}

int write_impl(const char* path, int w, int h, const void* pixels, int in_u8, int file_type, char* err, size_t n) try {
  const OIIO::TypeDesc type = file_type == 0 ? OIIO::TypeDesc::UINT8 : file_type == 1 ? OIIO::TypeDesc::HALF : OIIO::TypeDesc::FLOAT;
  OIIO::ImageSpec spec(w, h, 3, type);
  if (file_type == 0) spec.attribute("oiio:ColorSpace", "sRGB");
  auto out = OIIO::ImageOutput::create(path);
  if (!out) return fail(BTFC_IMAGEIO_CANNOT_OPEN, "no image writer: " + OIIO::geterror(), err, n);
  out->threads(1);
  if (!out->open(path, spec)) return fail(BTFC_IMAGEIO_CANNOT_OPEN, "cannot create: " + out->geterror(), err, n);
  if (!out->write_image(in_u8 ? OIIO::TypeDesc::UINT8 : OIIO::TypeDesc::FLOAT, pixels))
    return fail(BTFC_IMAGEIO_FAILED, "cannot write: " + out->geterror(), err, n);
  if (!out->close()) return fail(BTFC_IMAGEIO_FAILED, "cannot close: " + out->geterror(), err, n);
  return BTFC_IMAGEIO_OK;
} catch (const std::exception& e) {
  return fail(BTFC_IMAGEIO_FAILED, std::string("OpenImageIO: ") + e.what(), err, n);
}

const BtfcImageApi k_api{BTFC_IMAGEIO_API_VERSION, &info_impl, &read_impl, &write_impl};

}  // namespace

extern "C" __attribute__((visibility("default"))) const BtfcImageApi* btfc_imageio_api(void) { return &k_api; }
