// The explicit codec table. Adding a codec: one folder under codecs/ and one line here.
#include <string>
#include <vector>

#include "codecs/codec.h"
#include "codecs/fmf/fmf.h"
#include "codecs/lpca/lpca.h"
#include "codecs/lpyr/lpyr.h"
#include "codecs/mlvq/mlvq.h"

namespace btfc {
namespace {

struct Table {
  std::vector<CodecEntry> entries;
  std::vector<const Codec*> codecs;
};

Table& table() {
  static Table t = [] {
    Table r;
    r.entries = {
        {&fmf_codec(), &gpu::k_fmf_exporter},
        {&lpyr_codec(), &gpu::k_lpyr_exporter},
        {&lpca_codec(), &gpu::k_lpca_exporter},
        {&mlvq_codec(), &gpu::k_mlvq_exporter},
    };
    for (const CodecEntry& e : r.entries) r.codecs.push_back(e.codec);
    return r;
  }();
  return t;
}

}  // namespace

std::span<const CodecEntry> codec_registry() { return table().entries; }
std::span<const Codec* const> all_codecs() { return table().codecs; }

void register_codec(const CodecEntry& entry) {
  Table& t = table();
  if (!entry.codec || find_codec(entry.codec->name())) return;
  t.entries.push_back(entry);
  t.codecs.push_back(entry.codec);
}

const Codec* find_codec(const std::string& name) {
  for (const Codec* c : all_codecs())
    if (name == c->name()) return c;
  return nullptr;
}

}  // namespace btfc
