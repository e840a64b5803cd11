// libFuzzer target: spec-string parsing and binding (core/params.h). The input is parsed as a
// spec string, resolved through the registry (resolve_spec), and its key=value list is bound to
// every registered codec's parameter table, so each codec's ranges and choices are exercised,
// including codecs added later. A bound spec's canonical form must parse and bind again to the
// same canonical string (what .btfc files store and loaders re-read).
#include <string>

#include "tests/fuzz/fuzz_util.h"

using namespace btfc;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  (void)resolve_spec(text);
  auto s = parse_spec_string(text);
  if (!s.ok()) return 0;
  for (const Codec* c : all_codecs()) {
    auto p = bind_params(s.value(), c->params());
    if (!p.ok()) continue;
    (void)p->get_int(c->params().empty() ? std::string() : c->params()[0].name);
    auto again = parse_spec_string(p->canonical());
    if (!again.ok()) __builtin_trap();
    auto p2 = bind_params(again.value(), c->params());
    if (!p2.ok() || p2->canonical() != p->canonical()) __builtin_trap();
  }
  return 0;
}
