#include "formats/image_file.h"

#include <dlfcn.h>

#include <cstdlib>
#include <filesystem>
#include <mutex>
#include <vector>

#include "formats/imageio/imageio_api.h"

// Defined by a program built against the installed package (btfcConfig.cmake writes it: the
// plugin's path in that install); absent (null) everywhere else.
extern "C" const char btfc_imageio_plugin_path[] __attribute__((weak));

namespace btfc::image_file {
namespace {

namespace fs = std::filesystem;

struct Plugin {
  const BtfcImageApi* api = nullptr;
  std::string path;   // the file loaded
  std::string error;  // why none could be loaded
};

void anchor() {}  // an address inside the binary holding this code (dladdr)

Plugin load() {
  std::vector<std::string> tried;
  std::string last, loaded_path;
  auto attempt = [&](const std::string& path) -> const BtfcImageApi* {
    tried.push_back(path);
    void* h = dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL);
    if (!h) {
      if (fs::exists(path)) last = dlerror();  // a plugin that exists but does not load: say why
      return nullptr;
    }
    auto fn = reinterpret_cast<const BtfcImageApi* (*)()>(dlsym(h, "btfc_imageio_api"));
    const BtfcImageApi* api = fn ? fn() : nullptr;
    if (!api || api->version != BTFC_IMAGEIO_API_VERSION) {
      last = path + ": not a btfc image plugin of this version";
      dlclose(h);
      return nullptr;
    }
    loaded_path = path;
    return api;  // kept loaded for the process's life
  };
  const char* name = "libbtfc_imageio.so";
  if (const char* env = std::getenv("BTFC_IMAGEIO_PLUGIN"); env && *env) {
    if (const BtfcImageApi* api = attempt(env)) return {api, loaded_path, ""};
    return {nullptr, "", std::string("BTFC_IMAGEIO_PLUGIN=") + env + " cannot be loaded" + (last.empty() ? "" : ": " + last)};
  }
  if (const char* installed = btfc_imageio_plugin_path; installed != nullptr)  // weak: null when absent
    if (const BtfcImageApi* api = attempt(installed)) return {api, loaded_path, ""};
  Dl_info self{};
  if (dladdr(reinterpret_cast<void*>(&anchor), &self) && self.dli_fname) {
    std::error_code ec;
    const fs::path dir = fs::weakly_canonical(fs::path(self.dli_fname), ec).parent_path();
    for (const fs::path& p : {dir / name, dir.parent_path() / name, dir.parent_path() / "lib" / "btfc" / name,
                              dir.parent_path().parent_path() / "btfc" / name})
      if (const BtfcImageApi* api = attempt(p.string())) return {api, loaded_path, ""};
  }
#ifdef BTFC_IMAGEIO_INSTALL_PATH
  if (const BtfcImageApi* api = attempt(BTFC_IMAGEIO_INSTALL_PATH)) return {api, loaded_path, ""};
#endif
#ifdef BTFC_IMAGEIO_BUILD_PATH
  if (const BtfcImageApi* api = attempt(BTFC_IMAGEIO_BUILD_PATH)) return {api, loaded_path, ""};
#endif
  std::string msg = "image files need btfc's OpenImageIO plugin (libbtfc_imageio.so), which could not be loaded";
  if (!last.empty()) msg += ": " + last;
  msg += " (tried";
  for (const std::string& t : tried) msg += " " + t;
  return {nullptr, "", msg + "; BTFC_IMAGEIO_PLUGIN=PATH names it)"};
}

std::once_flag g_once;
Plugin g_plugin;

Result<const BtfcImageApi*> api() {
  std::call_once(g_once, [] { g_plugin = load(); });
  if (!g_plugin.api) return unsupported(g_plugin.error);
  return g_plugin.api;
}

Info from(const BtfcImageInfo& i) {
  Info o;
  o.width = i.width;
  o.height = i.height;
  o.depth = i.depth;
  o.channels = i.channels;
  o.is_uint8 = i.is_uint8 != 0;
  return o;
}

}  // namespace

Result<Info> info(const std::string& path) {
  BTFC_ASSIGN_OR_RETURN(const BtfcImageApi* a, api());
  BtfcImageInfo i{};
  char err[512] = "";
  const int rc = a->info(path.c_str(), &i, err, sizeof err);
  if (rc != BTFC_IMAGEIO_OK) return io_error(path + ": " + err);
  return from(i);
}

Result<Info> read_rgb(const std::string& path, int want_w, int want_h, uint8_t* u8, float* f32) {
  BTFC_ASSIGN_OR_RETURN(const BtfcImageApi* a, api());
  BtfcImageInfo i{};
  char err[512] = "";
  const int rc = a->read_rgb(path.c_str(), want_w, want_h, u8, f32, &i, err, sizeof err);
  Info o = from(i);
  if (rc == BTFC_IMAGEIO_SIZE) {
    o.size_ok = false;
    return o;
  }
  if (rc != BTFC_IMAGEIO_OK) return io_error(path + ": " + err);
  return o;
}

Status write_rgb(const std::string& path, const std::string& shown, int width, int height, const uint8_t* u8, const float* f32,
                 FileType type) {
  BTFC_ASSIGN_OR_RETURN(const BtfcImageApi* a, api());
  char err[512] = "";
  const int ft = type == FileType::srgb8 ? 0 : type == FileType::half ? 1 : 2;
  const void* pixels = u8 ? static_cast<const void*>(u8) : static_cast<const void*>(f32);
  if (a->write_rgb(path.c_str(), width, height, pixels, u8 ? 1 : 0, ft, err, sizeof err) != BTFC_IMAGEIO_OK)
    return io_error(shown + ": " + err);
  return {};
}

bool loaded() { return g_plugin.api != nullptr; }

std::string plugin_path() {
  (void)api();
  return g_plugin.path;
}

}  // namespace btfc::image_file
