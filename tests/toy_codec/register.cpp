// The toy codec's registration: the one line a codec outside the library needs (the library's
// own codecs have theirs in codecs/registry.cpp's table).
#include "codecs/codec.h"
#include "tests/toy_codec/toy.h"

namespace {
const bool k_toy_registered = (btfc::register_codec({&btfc::toy_codec(), &btfc::gpu::k_toy_exporter}), true);
}  // namespace
