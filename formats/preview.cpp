#include "formats/preview.h"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>

#include "formats/image_file.h"

namespace btfc {

Status write_rgb_image(const std::string& path, const RgbImage& img) {
  if (img.width <= 0 || img.height <= 0 || img.rgb.size() != size_t(img.width) * size_t(img.height) * 3)
    return invalid_argument(path + ": image size does not match its pixels");
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  if (ext != ".png" && ext != ".exr") return invalid_argument(path + ": image output must end in .png or .exr");
  const bool png = ext == ".png";
  // The temporary keeps the extension: OIIO picks the writer by it.
  const std::string tmp = path + ".tmp-" + std::to_string(getpid()) + ext;
  std::vector<uint8_t> bytes;
  if (png) {
    bytes.resize(img.rgb.size());
    for (size_t k = 0; k < bytes.size(); ++k) {
      const double c = std::isfinite(img.rgb[k]) ? std::clamp(double(img.rgb[k]), 0.0, 1.0) : 0.0;
      bytes[k] = uint8_t(std::lround(255.0 * (c <= 0.0031308 ? 12.92 * c : 1.055 * std::pow(c, 1.0 / 2.4) - 0.055)));
    }
  }
  Status s = png ? image_file::write_rgb(tmp, path, img.width, img.height, bytes.data(), nullptr, image_file::FileType::srgb8)
                 : image_file::write_rgb(tmp, path, img.width, img.height, nullptr, img.rgb.data(), image_file::FileType::half);
  if (!s.ok()) {
    std::remove(tmp.c_str());
    return s;
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    std::remove(tmp.c_str());
    return io_error(path + ": cannot rename the temporary file into place");
  }
  return {};
}

}  // namespace btfc
