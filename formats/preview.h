// Writing single RGB images (renders, side-by-side previews) through OpenImageIO (formats/image_file.h).
// The extension picks the format: .png -> 8-bit sRGB (values clamped to [0, 1], linear input
// encoded with the sRGB curve), .exr -> linear half float. Written to a temporary name and
// renamed, so a failure leaves no partial file; errors name the path.
#pragma once
#include <string>

#include "codecs/render.h"

namespace btfc {

Status write_rgb_image(const std::string& path, const RgbImage& img);

}  // namespace btfc
