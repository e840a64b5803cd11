// Reading and writing a BTF from/to any path a user gives. Reading goes through the reader table
// (formats/reader.h: image sets, Bonn .btf, .btfc raw or model); these are its one-call forms.
// Errors name the path. Written files appear atomically (temporary name, then rename).
#pragma once
#include <span>
#include <string>

#include "codecs/codec.h"
#include "core/btf.h"
#include "formats/image_set.h"

namespace btfc {

// The whole BTF at `path` (a model is decoded): open_input(path)->read().
Result<Btf> read_btf(const std::string& path);
// A model from a .btfc (any codec) or a Bonn .btf file (which already is a factorization):
// open_input(path)->take_model().
Result<std::unique_ptr<Model>> open_model(const std::string& path);
// Writes an fmf model as a Bonn .btf: DFMF for color=dfmf (colour model 11) and for models read
// from DFMF files, FMF for color=rgb. `half` selects IEEE half scalars (as Bonn's writers).
Status write_bonn(const Model& model, const std::string& path, bool half);
// Model writers, by the output path's extension: `.btfc` (the container, any codec) and `.btf`
// (Bonn FMF / DFMF, fmf models; half or float scalars as the model stores them).
struct ModelWriter {
  const char* name;
  const char* extension;
  // The spec to encode with for this output (Bonn DFMF files can only hold colour model 11's
  // fixed luminance offset 1e-5: an unset dfmf offset becomes that); sets *note when it changed.
  std::string (*adapt_spec)(const std::string& spec, std::string* note);
  Status (*write)(const Model& model, const std::string& path);
};
std::span<const ModelWriter> model_writers();
// The writer for `path` (by extension), or null.
const ModelWriter* model_writer_for(const std::string& path);
// The spec adapted for the writer of `path` (unchanged when none adapts it).
std::string spec_for_output(const std::string& spec, const std::string& path, std::string* note);
// Writes `model` by its path's writer; an unknown extension is an error naming the known ones.
Status write_model(const Model& model, const std::string& path);

// `.btfc` -> raw container; anything else -> image-set directory in `format`.
Status write_btf(const Btf& btf, const std::string& path, ImageFormat format = ImageFormat::exr);

}  // namespace btfc
