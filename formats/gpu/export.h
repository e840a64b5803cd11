// An export bundle (codecs/gpu_export.h: textures, shader, evaluation, filled by each codec's
// exporter) as files: `btfc export model.btfc --to DIR` writes
//   DIR/manifest.json   layout, formats, channel packing, scale/bias, direction tables, formula
//   DIR/<name>.ktx2     every texture (KTX 2.0, formats/gpu/ktx2.h)
//   DIR/btf.frag        GLSL ES 3.00 reference fragment shader
//   DIR/previews/       EXR (float) / PNG (8-bit, integer) image of each texture's layer 0, level 0
// so a viewer needs no btfc code. The directory appears whole or not at all (built under a
// temporary name, renamed on success).
#pragma once
#include <nlohmann/json.hpp>
#include <string>

#include "codecs/gpu_export.h"

namespace btfc::gpu {

// The whole manifest (textures, shader contract, evaluation, warnings).
nlohmann::json manifest_json(const ExportBundle& b);
// Writes DIR (KTX2 files, manifest, shader, and previews when `previews`); atomic as a whole.
// Defined in formats/export_dir.cpp (previews go through OpenImageIO).
Status write_export_dir(const ExportBundle& b, const std::string& dir, bool previews = true);

}  // namespace btfc::gpu
