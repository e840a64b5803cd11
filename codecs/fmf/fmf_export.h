// fmf GPU export extras (codecs/fmf/fmf_export.cpp; the exporter itself is in the table of
// formats/gpu/export.cpp).
#pragma once
#include <memory>

#include "formats/gpu/export.h"

namespace btfc::gpu {

// The fmf model restricted to what `opt.scene` needs, as the KTX2 export keeps it: eigen-textures
// box-filtered to the finest mip level the scene samples, the kept components, and the measured
// directions inside the (widened) cones. Without a scene (or a scene that keeps everything) it
// is the model itself. model.bsvtf of a scene export is built from it, so the streaming file
// holds only the scene's tiles, levels and packets.
Result<std::unique_ptr<Model>> fmf_scene_model(const Model& fmf_model, const ExportOptions& opt);

}  // namespace btfc::gpu
