// The BSVTF streaming file beside an export's textures (seed 000 sections 3-7): for a model that
// is a factorization (fmf_factors() succeeds), `btfc export` also writes DIR/model.bsvtf, the
// same model tiled for level-of-detail streaming (cut to the scene when the export has one).
#pragma once
#include "codecs/gpu_export.h"
#include "formats/bsvtf/bsvtf.h"

namespace btfc {

// Sets bundle.write_extra to write model.bsvtf when `model` has factors; `report` (kept alive by
// the caller until the bundle is written) receives what was written. Returns whether it did: not
// for a factorization in a Bonn colour model other than 0 and 11 (a warning in the bundle says
// so). A dfmf model of any luminance offset has one (colour model 11 or 13, bsvtf.h).
bool attach_bsvtf(gpu::ExportBundle& bundle, const Model& model, const gpu::ExportOptions& opt, const BsvtfOptions& bo,
                  BsvtfReport* report);

}  // namespace btfc
