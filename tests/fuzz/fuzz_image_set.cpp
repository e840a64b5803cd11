// libFuzzer target: the image-set reader (formats/image_set.h), which takes a directory: the
// files a user unpacked from a BTF archive (UBO2003 JPEGs, UTIA PNG / EXR, in tvTTT_pvPPP view
// folders or flat).
//
// Input: byte 0 = flags (bit 0: --allow-partial; bit 1: read_image_set(path) in one go instead
// of plan_image_set + read_image_set(plan)), then up to 16 entries, each
//   u8 name length, name (one optional '/': "tv000_pv000/tl000_pl000_tv000_pv000.exr"),
//   u16 LE data length, data (cut at the end of the input).
// The harness writes the entries into a fresh directory under /dev/shm (or $TMPDIR), reads it as
// a BTF image set and removes it. Missing images, mixed sizes or formats, duplicate angles, names
// that only almost match, broken PNG / JPEG / EXR bytes must all give a clean error naming the
// directory or the file; a set that reads must have the shape the plan said. The image decoders
// are OpenImageIO's (a plugin, not instrumented): a crash inside them is reported upstream, not
// fixed here; btfc's own code around them (listing, name parsing, set checks, sizes, sRGB
// conversion, the scatter into the BTF) must not crash.
// Seeds: tiny crops (2 x 2 .. 8 x 8 texels, 1-4 directions) of the real UBO2003 slice and of the
// textile, with their real file names (tests/fuzz/make_seeds.sh).
#include <stdlib.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include "formats/image_file.h"
#include "formats/image_set.h"
#include "tests/fuzz/fuzz_util.h"
#include "tests/fuzz/image_set_input.h"

using namespace btfc;
namespace fs = std::filesystem;

namespace {

std::string g_base;  // /dev/shm, else $TMPDIR, else /tmp

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  fuzz::init_process();
  const char* shm = "/dev/shm";
  g_base = fs::is_directory(shm) ? shm : (std::getenv("TMPDIR") ? std::getenv("TMPDIR") : "/tmp");
  // Without the OpenImageIO plugin every input would fail the same way: say so, do not fuzz.
  if (image_file::plugin_path().empty()) {
    std::fprintf(stderr, "fuzz_image_set: libbtfc_imageio.so cannot be loaded (BTFC_IMAGEIO_PLUGIN)\n");
    std::abort();
  }
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  // A fresh directory per input, removed at the end: libFuzzer's exits skip atexit handlers, so
  // nothing is left behind but the directory of an input that crashed.
  std::string dir = g_base + "/btfc-fuzz-imageset-XXXXXX";
  if (!mkdtemp(dir.data())) std::abort();
  std::error_code ec;
  const uint8_t flags = fuzz::write_image_set_entries(data, size, dir);
  set_allow_partial_image_sets((flags & 1) != 0);
  (void)is_image_set(dir);
  auto check_error = [&](const Status& s) {
    if (s.message().find(dir) == std::string::npos) {  // errors name the set or the file
      std::fprintf(stderr, "fuzz_image_set: error without the set's path: %s\n", s.message().c_str());
      __builtin_trap();
    }
  };
  if (flags & 2) {
    auto b = read_image_set(dir);
    if (!b.ok()) check_error(b.status());
  } else {
    auto plan = plan_image_set(dir);
    if (!plan.ok()) {
      check_error(plan.status());
    } else {
      if (plan->files.size() != plan->desc.num_lights() * plan->desc.num_views()) __builtin_trap();
      auto b = read_image_set(plan.value());
      if (!b.ok()) check_error(b.status());
      else if (b->desc().width != plan->desc.width || b->desc().height != plan->desc.height) __builtin_trap();
    }
  }
  fs::remove_all(dir, ec);
  return 0;
}
