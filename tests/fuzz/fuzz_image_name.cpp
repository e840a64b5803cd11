// libFuzzer target: the image-set name parsers (formats/image_set.h): file names
// ("00081 tl015 pl000 tv000 pv000.jpg", "tl015_pl000_tv000_pv000.exr") and view-folder names
// ("tv030_pv060"). Names come from directory listings of downloaded archives, so any bytes.
#include <string>

#include "formats/image_set.h"
#include "tests/fuzz/fuzz_util.h"

using namespace btfc;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string s(reinterpret_cast<const char*>(data), size);
  auto n = parse_image_name(s);
  // A parsed name must hold angles in [0, 360): the reader turns them into directions.
  if (n.ok() && (n->tl < 0 || n->tl >= 360 || n->pl < 0 || n->pl >= 360 || n->tv < 0 || n->tv >= 360 || n->pv < 0 || n->pv >= 360))
    __builtin_trap();
  (void)is_view_folder_name(s);
  return 0;
}
