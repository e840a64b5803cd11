// libFuzzer target: the .btfc container reader as a user's file meets it (CRCs included).
// Opens the input, verifies and reads every tensor, then loads it the way `btfc` does: raw BTFs
// through load_raw_btf, models through load_model (the codec registry) and a bounded decode.
// Any crash, sanitizer report, leak, or allocation above -malloc_limit_mb is a finding.
#include "core/container.h"
#include "tests/fuzz/fuzz_util.h"

using namespace btfc;

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  fuzz::init_process();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static fuzz::MemFile file;
  auto rd = ContainerReader::open(file.write(data, size));
  if (!rd.ok()) return 0;
  (void)rd->verify_all();
  for (const TensorInfo& t : rd->tensors()) (void)rd->read(t.name);
  if (rd->codec().name == "raw") {
    auto b = load_raw_btf(rd.value());
    if (b.ok()) (void)b->check_finite("fuzz");
    return 0;
  }
  auto m = load_model(rd.value());
  if (m.ok()) fuzz::exercise(*m.value());
  return 0;
}
