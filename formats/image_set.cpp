// Image-set BTF reader/writer (formats.md 2.1 / 2.3; contract in image_set.h). The image files
// go through OpenImageIO, loaded on first use (formats/image_file.h).
//
// Pixel orientation: texel (x, y) is column x, row y of the image file with y = 0 the *top* row
// (OIIO scanline 0), for every format. Colour: 8/16-bit integer images are sRGB-decoded with the
// exact sRGB EOTF (no OIIO colour conversion); EXR/HDR floats are taken as they are (UTIA EXRs are
// CIE XYZ: the three channels are kept in file order, not converted).
#include "formats/image_set.h"

#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <memory>
#include <regex>
#include <set>

#include "formats/image_file.h"

namespace btfc {
namespace fs = std::filesystem;
namespace {

constexpr double k_pi = 3.14159265358979323846;

double srgb_to_linear(double c) { return c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4); }
double linear_to_srgb(double c) { return c <= 0.0031308 ? 12.92 * c : 1.055 * std::pow(c, 1.0 / 2.4) - 0.055; }

const std::array<float, 256>& srgb_lut() {
  static const std::array<float, 256> lut = [] {
    std::array<float, 256> t{};
    for (int i = 0; i < 256; ++i) t[i] = float(srgb_to_linear(i / 255.0));
    return t;
  }();
  return lut;
}

// A view-folder name ends in "tv030_pv060".
const std::regex& view_dir_regex() {
  static const std::regex re(R"(tv\d{3}_pv\d{3}$)", std::regex::icase);
  return re;
}

// One direction as named in a file: whole degrees. At the pole phi is meaningless, so it is
// normalised to 0 ("tl000 pl090" and "tl000 pl000" are the same light).
struct Angles {
  int theta = 0, phi = 0;
  auto operator<=>(const Angles&) const = default;
};
Angles normalized(int theta, int phi) { return theta == 0 ? Angles{0, 0} : Angles{theta, phi}; }

Vec3 to_dir(Angles a) { return dir_from_theta_phi(a.theta * k_pi / 180.0, a.phi * k_pi / 180.0); }

// Orders the named directions: the UBO2003 order if the set is exactly that sampling, else
// sorted by (theta, phi) and identify()'d. Returns the set and each name's index in it.
DirectionSet make_set(const std::set<Angles>& names, std::map<Angles, int>& index) {
  DirectionSet s;
  index.clear();
  const DirectionSet ubo = DirectionSet::ubo2003();
  if (names.size() == ubo.size()) {
    std::vector<int> seen(ubo.size(), 0);
    bool all = true;
    for (const Angles& a : names) {
      int i = ubo.find(to_dir(a), 0.5 * k_pi / 180.0);
      if (i < 0 || seen[i]++) {
        all = false;
        break;
      }
      index[a] = i;
    }
    if (all) return ubo;
    index.clear();
  }
  for (const Angles& a : names) {  // std::set iterates in (theta, phi) order
    index[a] = int(s.dirs.size());
    s.dirs.push_back(to_dir(a));
  }
  s.identify();
  return s;
}

bool g_allow_partial = false;

// A direction set that is most of a standard sampling (UBO2003 81, UBO2014 151) but not all of
// it is almost certainly an image set with images missing: named, and refused unless
// --allow-partial (then read as the custom set of what is present).
Status check_complete(const std::string& path, const std::set<Angles>& names, const char* what) {
  for (const DirectionSet& full : {DirectionSet::ubo2003(), DirectionSet::ubo2014()}) {
    if (names.size() >= full.size() || names.size() * 2 <= full.size()) continue;
    std::vector<int> seen(full.size(), 0);
    bool subset = true;
    for (const Angles& a : names) {
      const int i = full.find(to_dir(a), 0.5 * k_pi / 180.0);
      if (i < 0) {
        subset = false;
        break;
      }
      seen[size_t(i)] = 1;
    }
    if (!subset) continue;
    std::string missing;
    size_t n = 0;
    for (size_t i = 0; i < full.size(); ++i) {
      if (seen[i]) continue;
      const Vec3& d = full.dirs[i];
      const int th = int(std::lround(std::acos(std::clamp(double(d.z), -1.0, 1.0)) * 180 / k_pi));
      const int ph = (int(std::lround(std::atan2(double(d.y), double(d.x)) * 180 / k_pi)) + 360) % 360;
      char buf[32];
      std::snprintf(buf, sizeof buf, "%st%c%03d p%c%03d", n ? ", " : "", what[0], th, what[0], th == 0 ? 0 : ph);
      if (++n <= 12) missing += buf;
    }
    if (n > 12) missing += ", ... (" + std::to_string(n - 12) + " more)";
    const std::string msg = path + ": incomplete image set: " + std::to_string(n) + " of the " + std::to_string(full.size()) + " " +
                            full.name + " " + what + " directions have no image: " + missing;
    if (!g_allow_partial) return corrupt_data(msg + " (--allow-partial reads the " + std::to_string(names.size()) + " present as a custom set)");
    std::fprintf(stderr, "warning: %s; read as a custom set of %zu (--allow-partial)\n", msg.c_str(), names.size());
  }
  return {};
}

struct ImageFile {
  fs::path path;
  int l = 0, v = 0;
};

// Colour encoding follows the format: EXR/HDR hold linear floats, JPEG/PNG sRGB-encoded integers.
bool is_linear_format(const fs::path& p) {
  std::string e = p.extension().string();
  std::transform(e.begin(), e.end(), e.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return e == ".exr" || e == ".hdr";
}

// Where images may sit: `dir` itself and its tvTTT_pvPPP subfolders.
std::vector<fs::path> image_folders(const fs::path& dir, std::error_code& ec) {
  std::vector<fs::path> folders{dir};
  for (const auto& e : fs::directory_iterator(dir, ec)) {
    const std::string name = e.path().filename().string();
    if (e.is_directory(ec) && is_view_folder_name(name)) folders.push_back(e.path());
  }
  return folders;
}

// A regular file with an image-set name. Other files (thumbnails, notes) are ignored, and so are
// hidden ones: unzipping on macOS leaves "._00000 tl000 ..." resource forks next to the images.
bool image_entry(const fs::directory_entry& e, ImageName& out) {
  std::error_code ec;
  const std::string name = e.path().filename().string();
  if (name.starts_with('.') || !e.is_regular_file(ec)) return false;
  Result<ImageName> n = parse_image_name(name);
  if (n.ok()) out = n.value();
  return n.ok();
}

Status list_images(const fs::path& dir, std::vector<std::pair<fs::path, ImageName>>& out) {
  std::error_code ec;
  const std::vector<fs::path> folders = image_folders(dir, ec);
  if (ec) return io_error(dir.string() + ": cannot list directory: " + ec.message());
  for (const fs::path& f : folders) {
    ImageName n;
    for (const auto& e : fs::directory_iterator(f, ec))
      if (image_entry(e, n)) out.emplace_back(e.path(), n);
    if (ec) return io_error(f.string() + ": cannot list directory: " + ec.message());
  }
  // Directory order is arbitrary; sort so that errors ("first missing pair") are deterministic.
  std::sort(out.begin(), out.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  return {};
}

// Reads images [first, last) of `files` (all of view v, lights l..l+n) into rows of `btf`.
// The images are decoded into a small per-thread buffer first, then scattered texel by texel:
// a texel's rows for consecutive lights are contiguous, so the scatter writes whole cache lines.
// Decodes images [first, last) into dst, image-major: dst[((i - first) * texels + t) * 3 + c].
Status decode_images(const std::vector<ImageFile>& files, size_t first, size_t last, const BtfDesc& d, float* out,
                     std::vector<uint8_t>& bytes) {
  const size_t px = d.num_texels();
  for (size_t i = first; i < last; ++i) {
    const std::string name = files[i].path.string();
    float* dst = out + (i - first) * px * 3;
    bytes.resize(px * 3);
    // 8-bit files of a non-linear format come as bytes (sRGB-decoded by the table below).
    BTFC_ASSIGN_OR_RETURN(const image_file::Info spec,
                          image_file::read_rgb(name, d.width, d.height, is_linear_format(files[i].path) ? nullptr : bytes.data(), dst));
    if (!spec.size_ok)
      return corrupt_data(name + ": image is " + std::to_string(spec.width) + "x" + std::to_string(spec.height) +
                          ", expected " + std::to_string(d.width) + "x" + std::to_string(d.height) + " (the size of " +
                          files[0].path.filename().string() + ")");
    if (spec.channels < 3)
      return unsupported(name + ": image has " + std::to_string(spec.channels) + " channels, need at least 3 (RGB)");
    if (spec.is_uint8) {
      const auto& lut = srgb_lut();
      for (size_t k = 0; k < px * 3; ++k) dst[k] = lut[bytes[k]];
    } else {
      if (is_linear_format(files[i].path)) {
        for (size_t k = 0; k < px * 3; ++k)
          if (!std::isfinite(dst[k]))
            return corrupt_data(name + ": non-finite pixel at (" + std::to_string(k / 3 % d.width) + ", " +
                                std::to_string(k / 3 / d.width) + ")");
      } else {  // 16-bit PNG etc.: OIIO normalised to [0, 1]; still sRGB-encoded
        for (size_t k = 0; k < px * 3; ++k) dst[k] = float(srgb_to_linear(dst[k]));
      }
    }
  }
  return {};
}

Status read_block(const std::vector<ImageFile>& files, size_t first, size_t last, Btf& btf, std::vector<float>& buf,
                  std::vector<uint8_t>& bytes) {
  const BtfDesc& d = btf.desc();
  const size_t px = d.num_texels();
  buf.resize((last - first) * px * 3);
  BTFC_RETURN_IF_ERROR(decode_images(files, first, last, d, buf.data(), bytes));
  const size_t n = last - first, v = size_t(files[first].v), l0 = size_t(files[first].l);
  for (size_t t = 0; t < px; ++t) {
    float* row = btf.abrdf(t) + d.row(l0, v, 0);
    for (size_t j = 0; j < n; ++j)
      for (int c = 0; c < 3; ++c) row[j * 3 + c] = buf[(j * px + t) * 3 + c];
  }
  return {};
}

Status plan_impl(const std::string& path, BtfDesc& desc, std::vector<ImageFile>& files) {
  std::error_code ec;
  const fs::path dir(path);
  if (!fs::exists(dir, ec)) return io_error(path + ": no such file or directory");
  if (!fs::is_directory(dir, ec)) return corrupt_data(path + ": not an image-set directory (not a directory)");
  std::vector<std::pair<fs::path, ImageName>> named;
  BTFC_RETURN_IF_ERROR(list_images(dir, named));
  if (named.empty())
    return corrupt_data(path + ": not an image set: no files named '... tlTTT plPPP tvTTT pvPPP.jpg|png|exr|hdr' "
                                   "in it or in tvTTT_pvPPP subfolders");

  std::set<Angles> light_names, view_names;
  for (const auto& [p, n] : named) {
    light_names.insert(normalized(n.tl, n.pl));
    view_names.insert(normalized(n.tv, n.pv));
  }
  std::map<Angles, int> li, vi;
  desc = BtfDesc{};
  desc.channels = 3;
  for (const auto& [p, n] : named) desc.hdr = desc.hdr || is_linear_format(p);
  BTFC_RETURN_IF_ERROR(check_complete(path, light_names, "light"));
  BTFC_RETURN_IF_ERROR(check_complete(path, view_names, "view"));
  desc.lights = make_set(light_names, li);
  desc.views = make_set(view_names, vi);

  // Exactly one image per (light, view) pair.
  const size_t nl = desc.num_lights(), nv = desc.num_views();
  std::vector<int> slot(nl * nv, -1);
  files.assign(nl * nv, ImageFile{});
  for (size_t k = 0; k < named.size(); ++k) {
    const ImageName& n = named[k].second;
    const int l = li[normalized(n.tl, n.pl)], v = vi[normalized(n.tv, n.pv)];
    const size_t s = size_t(l) + nl * size_t(v);
    if (slot[s] >= 0)
      return corrupt_data(path + ": two images for one (light, view) pair: " + named[slot[s]].first.string() + " and " +
                          named[k].first.string());
    slot[s] = int(k);
    files[s] = {named[k].first, l, v};
  }
  std::vector<Angles> lname(nl), vname(nv);  // index -> name, for the error message
  for (const auto& [a, i] : li) lname[size_t(i)] = a;
  for (const auto& [a, i] : vi) vname[size_t(i)] = a;
  for (size_t s = 0; s < slot.size(); ++s) {
    if (slot[s] >= 0) continue;
    char buf[96];
    const Angles l = lname[s % nl], v = vname[s / nl];
    std::snprintf(buf, sizeof buf, "tl%03d pl%03d tv%03d pv%03d", l.theta, l.phi, v.theta, v.phi);
    return corrupt_data(path + ": missing image for light/view pair " + buf + " (" + std::to_string(named.size()) +
                        " images for " + std::to_string(nl) + " lights x " + std::to_string(nv) + " views)");
  }

  // The first image fixes the size.
  {
    BTFC_ASSIGN_OR_RETURN(const image_file::Info first, image_file::info(files[0].path.string()));
    desc.width = first.width;
    desc.height = first.height;
  }
  return desc.validate().with_context(path);
}

// `path`, the set's directory, names the set in the error of a BTF too large for the memory limit.
Result<Btf> read_planned(const std::string& path, const BtfDesc& desc, const std::vector<ImageFile>& files) {
  Result<Btf> created = Btf::create(desc);
  if (!created.ok()) return created.status().with_context(path);
  Btf btf = std::move(created).value();
  const size_t nl = desc.num_lights(), nv = desc.num_views();

  // Work items: blocks of consecutive lights of one view, each decoded into <= ~32 MB.
  const size_t img_bytes = desc.num_texels() * 3 * sizeof(float);
  const size_t max_block = std::clamp<size_t>((size_t(32) << 20) / img_bytes, 1, 16);
  const size_t blocks_per_view = (nl + max_block - 1) / max_block;
  const size_t block = (nl + blocks_per_view - 1) / blocks_per_view;  // even blocks: 81 -> 6 x 14
  const long items = long(nv * blocks_per_view);
  std::vector<Status> errors(static_cast<size_t>(items));
  std::atomic<bool> failed{false};
#pragma omp parallel
  {
    std::vector<float> buf;
    std::vector<uint8_t> bytes;
#pragma omp for schedule(dynamic, 1)
    for (long it = 0; it < items; ++it) {
      const size_t v = size_t(it) / blocks_per_view, l0 = (size_t(it) % blocks_per_view) * block;
      if (failed || l0 >= nl) continue;
      const size_t first = l0 + nl * v, last = std::min(l0 + block, nl) + nl * v;
      try {
        errors[it] = read_block(files, first, last, btf, buf, bytes);
      } catch (const std::exception& e) {
        errors[it] = io_error(files[first].path.string() + " (or the next images of its view): " + e.what());
      }
      if (!errors[it].ok()) failed = true;
    }
  }
  for (const Status& s : errors)
    if (!s.ok()) return s;
  return btf;
}

Result<Btf> read_impl(const std::string& path) {
  BtfDesc desc;
  std::vector<ImageFile> files;
  BTFC_RETURN_IF_ERROR(plan_impl(path, desc, files));
  return read_planned(path, desc, files);
}

}  // namespace

void set_allow_partial_image_sets(bool allow) { g_allow_partial = allow; }

Result<ImageName> parse_image_name(const std::string& filename) {
  // Angles at the end of the name; each separator may be ' ' (UBO2003) or '_' (UTIA). Anything
  // before "tl" (the UBO2003 sequence number) is ignored but must end in a separator.
  static const std::regex re(R"((?:^|.*[ _])tl(\d{3})[ _]pl(\d{3})[ _]tv(\d{3})[ _]pv(\d{3})\.(jpe?g|png|exr|hdr))",
                             std::regex::icase);
  const std::string base = fs::path(filename).filename().string();
  // libstdc++'s regex matcher recurses once per character of ".*": a name of 40 KB overflowed
  // the stack (tests/corrupt/handmade_long_name.name). No file system stores a name longer than
  // 255 bytes (NAME_MAX), so longer ones are rejected before matching.
  if (base.size() > 255)
    return invalid_argument(base.substr(0, 40) + "...: not an image-set name (" + std::to_string(base.size()) +
                            " bytes, longer than any file name)");
  std::smatch m;
  if (!std::regex_match(base, m, re))
    return invalid_argument(base + ": not an image-set name (expected '... tlTTT plPPP tvTTT pvPPP.jpg' or "
                                   "'tlTTT_plPPP_tvTTT_pvPPP.png|exr|hdr')");
  ImageName n{std::stoi(m[1]), std::stoi(m[2]), std::stoi(m[3]), std::stoi(m[4])};
  if (n.tl >= 360 || n.pl >= 360 || n.tv >= 360 || n.pv >= 360)
    return invalid_argument(base + ": angle of 360 degrees or more");
  return n;
}

bool is_view_folder_name(const std::string& name) { return std::regex_search(name, view_dir_regex()); }

bool is_image_set(const std::string& path) {
  try {
    std::error_code ec;
    if (!fs::is_directory(path, ec)) return false;
    ImageName n;
    for (const fs::path& f : image_folders(path, ec))
      for (const auto& e : fs::directory_iterator(f, ec))
        if (image_entry(e, n)) return true;
  } catch (...) {  // is_image_set is a yes/no probe
  }
  return false;
}

Result<ImageSetPlan> plan_image_set(const std::string& path) {
  try {
    ImageSetPlan p;
    p.path = path;
    std::vector<ImageFile> files;
    BTFC_RETURN_IF_ERROR(plan_impl(path, p.desc, files));
    for (const ImageFile& f : files) p.files.push_back(f.path.string());
    return p;
  } catch (const std::exception& e) {
    return io_error(path + ": " + e.what());
  }
}

Result<Btf> read_image_set(const ImageSetPlan& plan) {
  std::vector<ImageFile> files(plan.files.size());
  for (size_t i = 0; i < files.size(); ++i) files[i] = {plan.files[i], int(i % plan.desc.num_lights()), int(i / plan.desc.num_lights())};
  try {
    return read_planned(plan.path, plan.desc, files);
  } catch (const std::bad_alloc&) {
    return io_error(plan.path + ": out of memory reading the image set");
  } catch (const std::exception& e) {
    return io_error(plan.path + ": " + e.what());
  }
}

Status read_images(const ImageSetPlan& plan, size_t first, size_t last, float* dst) {
  if (first > last || last > plan.files.size()) return invalid_argument(plan.path + ": image range outside the set");
  const size_t px = plan.desc.num_texels();
  const long n = long(last - first);
  std::vector<Status> errors(static_cast<size_t>(n));
  std::vector<ImageFile> files(plan.files.size());
  for (size_t i = 0; i < files.size(); ++i) files[i] = {plan.files[i], int(i % plan.desc.num_lights()), int(i / plan.desc.num_lights())};
#pragma omp parallel
  {
    std::vector<uint8_t> bytes;
#pragma omp for schedule(dynamic, 1)
    for (long i = 0; i < n; ++i) {
      try {
        errors[size_t(i)] = decode_images(files, first + size_t(i), first + size_t(i) + 1, plan.desc, dst + size_t(i) * px * 3, bytes);
      } catch (const std::exception& e) {
        errors[size_t(i)] = io_error(plan.files[first + size_t(i)] + ": " + e.what());
      }
    }
  }
  for (const Status& s : errors)
    if (!s.ok()) return s;
  return {};
}

Result<Btf> read_image_set(const std::string& path) {
  try {
    return read_impl(path);
  } catch (const std::bad_alloc&) {
    return io_error(path + ": out of memory reading the image set");
  } catch (const std::exception& e) {
    return io_error(path + ": " + e.what());
  }
}

namespace {

// "tl015_pl060": whole degrees; at the pole phi is 0 whatever float noise says.
Angles round_angles(const Vec3& d) {
  double theta, phi;
  dir_to_theta_phi(d, theta, phi);
  int t = int(std::lround(theta * 180.0 / k_pi)), p = int(std::lround(phi * 180.0 / k_pi)) % 360;
  return normalized(t, p);
}

Result<std::vector<Angles>> name_set(const DirectionSet& s, const char* what) {
  std::vector<Angles> out;
  std::map<Angles, size_t> seen;
  for (size_t i = 0; i < s.size(); ++i) {
    Angles a = round_angles(s.dirs[i]);
    if (auto it = seen.find(a); it != seen.end())
      return invalid_argument(std::string("cannot write image set: ") + what + " directions " + std::to_string(it->second) +
                              " and " + std::to_string(i) + " both round to theta " + std::to_string(a.theta) +
                              " phi " + std::to_string(a.phi) + " degrees");
    seen[a] = i;
    out.push_back(a);
  }
  return out;
}

// Writes image (l, v) to `file` (inside the temp directory); errors name `shown`, its final path.
Status write_one(const Btf& btf, size_t l, size_t v, const std::string& file, const std::string& shown,
                 ImageFormat format, image_file::FileType exr_type, std::vector<float>& buf, std::vector<uint8_t>& bytes) {
  const BtfDesc& d = btf.desc();
  const ImageView img = btf.image(l, v);
  buf.resize(d.num_texels() * 3);
  for (int y = 0; y < d.height; ++y)
    for (int x = 0; x < d.width; ++x)
      for (int c = 0; c < 3; ++c) {
        const float val = img.at(x, y, c);
        if (!std::isfinite(val))
          return invalid_argument(shown + ": non-finite value at texel (" + std::to_string(x) + ", " + std::to_string(y) + ")");
        buf[(size_t(y) * d.width + x) * 3 + c] = val;
      }
  if (format == ImageFormat::png) {
    bytes.resize(buf.size());
    for (size_t k = 0; k < buf.size(); ++k)
      bytes[k] = uint8_t(std::lround(255.0 * linear_to_srgb(std::clamp(double(buf[k]), 0.0, 1.0))));
    return image_file::write_rgb(file, shown, d.width, d.height, bytes.data(), nullptr, image_file::FileType::srgb8);
  }
  return image_file::write_rgb(file, shown, d.width, d.height, nullptr, buf.data(), exr_type);
}

// Writes an image set into a temporary directory next to `dir`, part by part, and renames it
// into place at the end (no partial output): `part` holds the images of lights
// [l0, l0 + part lights) and views [v0, v0 + part views) of the whole set `d`.
class SetWriter {
 public:
  Status open(const BtfDesc& d, const std::string& dir_in, ImageFormat format) {
    m_format = format;
    if (d.channels != 3)
      return unsupported("cannot write image set " + dir_in + ": " + std::to_string(d.channels) + " channels, need 3 (RGB)");
    BTFC_ASSIGN_OR_RETURN(m_ln, name_set(d.lights, "light"));
    BTFC_ASSIGN_OR_RETURN(m_vn, name_set(d.views, "view"));
    m_dir = dir_in;
    while (m_dir.size() > 1 && m_dir.back() == '/') m_dir.pop_back();
    std::error_code ec;
    const fs::path dir(m_dir);
    if (fs::exists(dir, ec) && !(fs::is_directory(dir, ec) && fs::is_empty(dir, ec)))
      return io_error(m_dir + ": already exists and is not an empty directory");
    m_tmp = fs::path(m_dir + ".tmp-" + std::to_string(getpid()));
    fs::remove_all(m_tmp, ec);  // a stale temp of an earlier process with our pid
    for (size_t v = 0; v < d.num_views(); ++v) {
      char sub[32];
      std::snprintf(sub, sizeof sub, "tv%03d_pv%03d", m_vn[v].theta, m_vn[v].phi);
      if (!fs::create_directories(m_tmp / sub, ec) && ec) return fail(io_error((m_tmp / sub).string() + ": cannot create: " + ec.message()));
    }
    m_open = true;
    return {};
  }
  ~SetWriter() {
    std::error_code ec;
    if (m_open) fs::remove_all(m_tmp, ec);
  }

  Status write(const Btf& part, size_t l0, size_t v0) {
    const BtfDesc& pd = part.desc();
    // Half keeps EXRs small (UTIA stores half); values beyond its range (HDR) need float.
    image_file::FileType exr_type = image_file::FileType::half;
    for (size_t i = 0; i < part.size() && m_format == ImageFormat::exr; ++i)
      if (std::fabs(part.data()[i]) > 65000.0f) {
        exr_type = image_file::FileType::float32;
        break;
      }
    const char* ext = m_format == ImageFormat::exr ? "exr" : "png";
    const size_t nl = pd.num_lights(), nv = pd.num_views();
    const long items = long(nl * nv);
    std::vector<Status> errors(static_cast<size_t>(items));
    std::atomic<bool> failed{false};
#pragma omp parallel
    {
      std::vector<float> buf;
      std::vector<uint8_t> bytes;
#pragma omp for schedule(dynamic, 4)
      for (long it = 0; it < items; ++it) {
        if (failed) continue;
        const size_t l = size_t(it) % nl, v = size_t(it) / nl, gl = l0 + l, gv = v0 + v;
        char name[96];
        std::snprintf(name, sizeof name, "tv%03d_pv%03d/tl%03d_pl%03d_tv%03d_pv%03d.%s", m_vn[gv].theta, m_vn[gv].phi, m_ln[gl].theta,
                      m_ln[gl].phi, m_vn[gv].theta, m_vn[gv].phi, ext);
        const std::string shown = m_dir + "/" + name;
        try {
          errors[it] = write_one(part, l, v, (m_tmp / name).string(), shown, m_format, exr_type, buf, bytes);
        } catch (const std::exception& e) {
          errors[it] = io_error(shown + ": " + e.what());
        }
        if (!errors[it].ok()) failed = true;
      }
    }
    for (const Status& e : errors)
      if (!e.ok()) return fail(e);
    return {};
  }

  Status finish() {
    std::error_code ec;
    fs::rename(m_tmp, fs::path(m_dir), ec);  // replaces an empty `dir` atomically (rename(2))
    if (ec) return fail(io_error(m_dir + ": cannot rename " + m_tmp.string() + " into place: " + ec.message()));
    m_open = false;
    return {};
  }

 private:
  Status fail(Status s) {
    std::error_code ec;
    fs::remove_all(m_tmp, ec);
    m_open = false;
    return s;
  }
  ImageFormat m_format = ImageFormat::exr;
  std::vector<Angles> m_ln, m_vn;
  std::string m_dir;
  fs::path m_tmp;
  bool m_open = false;
};

Status write_impl(const Btf& btf, const std::string& dir, ImageFormat format) {
  SetWriter w;
  BTFC_RETURN_IF_ERROR(w.open(btf.desc(), dir, format));
  BTFC_RETURN_IF_ERROR(w.write(btf, 0, 0));
  return w.finish();
}

Status write_streamed_impl(const BtfDesc& d, const std::string& dir, ImageFormat format, size_t max_bytes, const ImagePartFn& decode) {
  // One view's lights at a time, as many as fit: the decoded part (float) plus the writer
  // threads' one-image buffers.
  const uint64_t image_bytes = d.num_texels() * uint64_t(d.channels) * 4;
  if (2 * image_bytes > max_bytes)
    return invalid_argument(dir + ": one image of " + std::to_string(d.width) + "x" + std::to_string(d.height) + " texels needs " +
                            std::to_string(2 * image_bytes) + " bytes to decode and write, more than the limit of " + std::to_string(max_bytes));
  SetWriter w;
  BTFC_RETURN_IF_ERROR(w.open(d, dir, format));
  const size_t group = size_t(std::clamp<uint64_t>(max_bytes / std::max<uint64_t>(image_bytes, 1) / 2, 1, d.num_lights()));
  Btf part;
  for (size_t v = 0; v < d.num_views(); ++v)
    for (size_t l0 = 0; l0 < d.num_lights(); l0 += group) {
      const size_t n = std::min(group, d.num_lights() - l0);
      BTFC_RETURN_IF_ERROR(decode(v, l0, n, part));
      if (part.desc().num_lights() != n || part.desc().num_views() != 1 || part.desc().num_texels() != d.num_texels())
        return invalid_argument(dir + ": a decoded part has the wrong shape");
      BTFC_RETURN_IF_ERROR(w.write(part, l0, v));
    }
  return w.finish();
}

}  // namespace

Status write_image_set(const Btf& btf, const std::string& dir, ImageFormat format) {
  try {
    return write_impl(btf, dir, format);
  } catch (const std::exception& e) {
    return io_error(dir + ": " + e.what());
  }
}

Status write_image_set_streamed(const BtfDesc& desc, const std::string& dir, ImageFormat format, size_t max_bytes,
                                const ImagePartFn& decode) {
  try {
    return write_streamed_impl(desc, dir, format, max_bytes, decode);
  } catch (const std::exception& e) {
    return io_error(dir + ": " + e.what());
  }
}

}  // namespace btfc
