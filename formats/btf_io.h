// Reading and writing a BTF from/to any path a user gives, by its shape:
//   *.btfc holding codec "raw"  -> the uncompressed container (core/container.h)
//   *.btfc holding a model      -> loaded and fully decoded (read_btf only)
//   a directory                 -> an image set (formats/image_set.h): UBO2003 or UTIA layout
//   a Bonn binary .btf          -> DFMF / FMF / PVF / BDI (formats/bonn/bonn_btf.h), fully decoded
// Errors name the path. Written files appear atomically (temporary name, then rename).
#pragma once
#include <string>

#include "codecs/codec.h"
#include "core/btf.h"
#include "formats/image_set.h"

namespace btfc {

Result<Btf> read_btf(const std::string& path);
// A model from a .btfc (any codec) or a Bonn .btf file (which already is a factorization).
Result<std::unique_ptr<Model>> open_model(const std::string& path);
// Writes an fmf model as a Bonn .btf: DFMF for color=dfmf (colour model 11) and for models read
// from DFMF files, FMF for color=rgb. `half` selects IEEE half scalars (as Bonn's writers).
Status write_bonn(const Model& model, const std::string& path, bool half);
// `.btfc` -> raw container; anything else -> image-set directory in `format`.
Status write_btf(const Btf& btf, const std::string& path, ImageFormat format = ImageFormat::exr);

}  // namespace btfc
