// Image-set BTFs (formats.md 2.1 / 2.3): one image per (light, view).
//
//   UBO2003: <dir>/tvTTT_pvPPP/NNNNN tlTTT plPPP tvTTT pvPPP.jpg   (8-bit sRGB JPEG)
//   UTIA:    <dir>/tvTTT_pvPPP/tlTTT_plPPP_tvTTT_pvPPP.png|.exr   (PNG sRGB 8-bit, EXR linear)
// Angles are whole degrees parsed from the *end* of each name (tl/pl/tv/pv), not the prefix.
// `dir` may also be a single view folder (tvTTT_pvPPP) itself.
//
// Contracts:
//  - 8-bit images are sRGB-decoded to linear float; EXR/HDR values are kept linear (desc.hdr).
//  - Subsets are accepted (but see set_allow_partial_image_sets): the light set is the sorted union of lights seen, the view set
//    the union of views; every (light, view) pair of that product must have exactly one image,
//    otherwise the error names the first missing pair. Sets equal to the UBO2003 81 sampling get
//    its index order (ring, then phi) and name.
//  - All images must have the same size and >= 3 channels (the first 3 are used); a mismatch, an
//    unreadable image, or a non-finite pixel is an error naming the file.
//  - The writer writes the UTIA layout (EXR linear half/float, or PNG 8-bit sRGB) to a temp
//    directory renamed on success.
#pragma once
#include <functional>
#include <string>
#include <vector>

#include "core/btf.h"

namespace btfc {

struct ImageName {
  int tl = 0, pl = 0, tv = 0, pv = 0;  // degrees
};
// Parses the four angles from the end of a file name ("00081 tl015 pl000 tv000 pv000.jpg" or
// "tl015_pl000_tv000_pv000.exr"). Fails on names of another shape; angles must be < 360.
Result<ImageName> parse_image_name(const std::string& filename);

// True for a view-folder name: one ending in "tvTTT_pvPPP" (case-insensitive).
bool is_view_folder_name(const std::string& name);

// Cheap check: does `path` look like an image-set directory?
bool is_image_set(const std::string& path);

Result<Btf> read_image_set(const std::string& path);
// A set whose lights (or views) are most but not all of UBO2003 / UBO2014 is refused as
// incomplete, naming the missing directions, unless this is set (btfc --allow-partial): then it
// is read as the custom set of what is present, with a warning on stderr.
void set_allow_partial_image_sets(bool allow);

// Streaming (out-of-core) reading: the set's shape and its image files in BTF row order
// (image i = light + nL * view), checked as read_image_set checks them, without the pixels.
struct ImageSetPlan {
  std::string path;
  BtfDesc desc;
  std::vector<std::string> files;
};
Result<ImageSetPlan> plan_image_set(const std::string& path);
// Images [first, last) of the plan, image-major: dst[((i - first) * texels + t) * 3 + c]
// (decoded in parallel; same conversions and errors as read_image_set).
Status read_images(const ImageSetPlan& plan, size_t first, size_t last, float* dst);
// The whole set of a plan (read_image_set without planning again).
Result<Btf> read_image_set(const ImageSetPlan& plan);

enum class ImageFormat { exr, png };
Status write_image_set(const Btf& btf, const std::string& dir, ImageFormat format);
// The same for a BTF that is never whole in memory: decode(v, l0, n, part) fills `part` with
// view v's lights [l0, l0 + n) at every texel; parts of at most about max_bytes / 2 are asked
// for, one view at a time. The set appears under `dir` only when complete. An EXR part with
// values beyond the half range is written as float (per part, so a set may mix the two).
using ImagePartFn = std::function<Status(size_t view, size_t light0, size_t lights, Btf& part)>;
Status write_image_set_streamed(const BtfDesc& desc, const std::string& dir, ImageFormat format, size_t max_bytes,
                                const ImagePartFn& decode);

}  // namespace btfc
