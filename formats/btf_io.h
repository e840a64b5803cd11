// Reading and writing a BTF from/to any path a user gives, by its shape:
//   *.btfc holding codec "raw"  -> the uncompressed container (core/container.h)
//   *.btfc holding a model      -> loaded and fully decoded (read_btf only)
//   a directory                 -> an image set (formats/image_set.h): UBO2003 or UTIA layout
// Errors name the path. Written files appear atomically (temporary name, then rename).
#pragma once
#include <string>

#include "core/btf.h"
#include "formats/image_set.h"

namespace btfc {

Result<Btf> read_btf(const std::string& path);
// `.btfc` -> raw container; anything else -> image-set directory in `format`.
Status write_btf(const Btf& btf, const std::string& path, ImageFormat format = ImageFormat::exr);

}  // namespace btfc
