// libFuzzer target: the Bonn binary .btf readers (formats/bonn: DFMF, FMF, PVF, BDI). Parses
// the header-only path (read_bonn_info, what `btfc info` uses), then opens the file as a model
// and decodes a bounded piece (BDI reads and bzip2-inflates texel chunks on demand there).
#include "formats/bonn/bonn_btf.h"
#include "tests/fuzz/fuzz_util.h"

using namespace btfc;

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  fuzz::init_process();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static fuzz::MemFile file;
  const std::string& path = file.write(data, size);
  if (!is_bonn_btf(path)) return 0;
  auto info = read_bonn_info(path);
  if (info.ok()) (void)info->notes();
  auto m = open_bonn_model(path);
  if (m.ok()) fuzz::exercise(*m.value());
  return 0;
}
