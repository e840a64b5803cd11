// libFuzzer target: the mlvq codec's entropy-coded index streams (codecs/mlvq/huffman.cpp), fed
// directly rather than through a .btfc container, so every mutation reaches the decoder.
//
// Input: byte 0 picks the mode.
//  - even: decode. Bytes 1-4 = count (u32 LE), 5-8 = alphabet (u32 LE), the rest = the stream
//    (mode byte 0 plain / 1 canonical Huffman, then the bits), exactly what MlvqModel::load
//    passes for a codebook's child indices, the merge book and the texel indices (counts up to
//    2^28 x 64 and alphabets up to 2^28 come from the file there). decode_indices must return
//    exactly `count` indices < alphabet or an error, with no allocation beyond what the stream
//    (or, for a 1-symbol alphabet that stores no bits, the memory limit) allows.
//  - odd: round trip. Bytes 1-2 = alphabet (u16 LE, + 1), the rest = indices (2 bytes each,
//    modulo the alphabet); bit 1 of byte 0 allows Huffman. encode_indices then decode_indices
//    must give the indices back, in the smaller of the two codings it reports.
// Seeds: the index tensors of tests/golden/mlvq.btfc and of an mlvq model of a crop of the real
// UBO2003 slice, with their count and alphabet (tests/fuzz/make_seeds.sh).
#include <vector>

#include "codecs/mlvq/mlvq_internal.h"
#include "tests/fuzz/fuzz_util.h"

using namespace btfc;

namespace {
uint32_t rd32(const uint8_t* p) { return uint32_t(p[0]) | uint32_t(p[1]) << 8 | uint32_t(p[2]) << 16 | uint32_t(p[3]) << 24; }
}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  fuzz::init_process();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  if ((data[0] & 1) == 0) {
    if (size < 9) return 0;
    const uint32_t count = rd32(data + 1), alphabet = rd32(data + 5);
    auto r = mlvq::decode_indices(std::span<const uint8_t>(data + 9, size - 9), count, alphabet, "fuzz stream");
    if (!r.ok()) {
      if (r.status().message().find("fuzz stream") == std::string::npos) __builtin_trap();
      return 0;
    }
    if (r->size() != count) __builtin_trap();
    for (uint32_t x : r.value())
      if (x >= alphabet) __builtin_trap();
    return 0;
  }
  if (size < 3) return 0;
  const uint32_t alphabet = (uint32_t(data[1]) | uint32_t(data[2]) << 8) + 1;
  std::vector<uint32_t> v;
  for (size_t i = 3; i + 1 < size; i += 2) v.push_back((uint32_t(data[i]) | uint32_t(data[i + 1]) << 8) % alphabet);
  const mlvq::CodedStream cs = mlvq::encode_indices(v, alphabet, (data[0] & 2) != 0);
  if (cs.bytes.size() != (cs.huffman ? cs.huffman_bytes : cs.plain_bytes)) __builtin_trap();
  if (cs.huffman && cs.huffman_bytes >= cs.plain_bytes) __builtin_trap();
  auto back = mlvq::decode_indices(cs.bytes, v.size(), alphabet, "round trip");
  if (!back.ok() || back.value() != v) __builtin_trap();
  return 0;
}
