// attach_bsvtf (formats/bsvtf/bsvtf_export.h).
#include "formats/bsvtf/bsvtf_export.h"

#include "codecs/fmf/fmf.h"
#include "core/params.h"

namespace btfc {

bool attach_bsvtf(gpu::ExportBundle& bundle, const Model& model, const gpu::ExportOptions& opt, const BsvtfOptions& bo,
                  BsvtfReport* report) {
  auto fv = fmf_factors(model);
  if (!fv.ok()) return false;
  if (fv->per_channel && fv->drr_eps != 1e-5f) {
    // The textures hold any offset (evaluation.luminance_offset); the pinned BSVTF format holds
    // colour model 11's only, so the export goes on without it rather than failing.
    bundle.warnings.push_back("model.bsvtf not written: BSVTF stores Bonn's colour model 11 (luminance offset 1e-5) only, this dfmf model's offset is " +
                              real_string(fv->drr_eps) + " (encode with fmf:color=dfmf:offset=1e-5 for a BSVTF file)");
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
