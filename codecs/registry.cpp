// The explicit codec table. Adding a codec: one folder under codecs/ and one line here.
#include "codecs/codec.h"
#include "codecs/fmf/fmf.h"
#include "codecs/lpca/lpca.h"
#include "codecs/lpyr/lpyr.h"
#include "codecs/mlvq/mlvq.h"

namespace btfc {

std::span<const Codec* const> all_codecs() {
  static const Codec* const k_codecs[] = {
      &fmf_codec(),
      &lpyr_codec(),
      &lpca_codec(),
      &mlvq_codec(),
  };
  return k_codecs;
}

const Codec* find_codec(const std::string& name) {
  for (const Codec* c : all_codecs())
    if (name == c->name()) return c;
  return nullptr;
}

}  // namespace btfc
