// attach_bsvtf (formats/bsvtf/bsvtf_export.h).
#include "formats/bsvtf/bsvtf_export.h"

#include "codecs/fmf/fmf.h"
#include "core/params.h"

namespace btfc {

bool attach_bsvtf(gpu::ExportBundle& bundle, const Model& model, const gpu::ExportOptions& opt, const BsvtfOptions& bo,
                  BsvtfReport* report) {
  auto fv = fmf_factors(model);
  if (!fv.ok()) return false;
  if (bsvtf_color_model(*fv) < 0) {
    // A factorization read from a Bonn file in another colour model: its textures export, and
    // the export goes on without the streaming file rather than failing (write_bsvtf: unsupported).
    bundle.warnings.push_back("model.bsvtf not written: BSVTF stores FMF rgb and DFMF (Bonn colour models 0 and 11), this model's is " +
                              std::to_string(fv->bonn_color_model));
    return false;
  }
  bundle.write_extra = [&model, opt, bo, report](const std::string& dir) -> Result<nlohmann::json> {
    std::unique_ptr<Model> cut;  // a scene keeps only its levels, components and directions
    if (opt.scene) {
      BTFC_ASSIGN_OR_RETURN(cut, gpu::fmf_scene_model(model, opt));
    }
    BsvtfReport local;
    BsvtfReport& r = report ? *report : local;
    BTFC_RETURN_IF_ERROR(write_bsvtf(cut ? *cut : model, bo, dir + "/model.bsvtf", &r));
    return nlohmann::json::array({{{"file", "model.bsvtf"},
                                   {"meaning", "BSVTF streaming file (docs/FORMAT.md): eigen-textures as 64 x 64 DCT tiles with 4 px borders, "
                                               "mip levels as residuals to the parent, eigen-ABRDF packets"},
                                   {"quality", bo.quality},
                                   {"bytes", r.file_bytes},
                                   {"tiles", r.tiles},
                                   {"eigen_texture_psnr_db", r.psnr}}});
  };
  return true;
}

}  // namespace btfc
