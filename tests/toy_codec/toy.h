// Codec `toy`: a codec that exists only in the tests, the proof that a new codec is one folder
// and one line (docs/ARCHITECTURE.md, "Adding a codec"). It is registered by one line in
// tests/toy_codec/register.cpp and then runs through the generic codec, container, export and
// bench contracts (tests/codec_contract_test.cpp) that every registered codec passes.
//
// Model (a rank-1 factorization with the mean ABRDF as its basis; no paper, by design):
//   value(x, y, row) = gain(x, y) * mean(row),  mean = the texels' average ABRDF,
//   gain(x, y) = <B_xy, mean> / <mean, mean> (least squares; 0 for an all-zero mean),
// or gain = 1 with `gain=one` (the plain mean). Arbitrary directions: Delaunay (9 lookups).
//
// Stored tensors (payload version 1): mean f32 [abrdf_size], gain f32 [H, W].
// GPU export (toy_export.cpp): mean as an RGBA32F nL x nV texture, gain as R32F W x H.
#pragma once
#include "codecs/codec.h"

namespace btfc {

const Codec& toy_codec();
namespace gpu {
struct Exporter;
extern const Exporter k_toy_exporter;
}  // namespace gpu

}  // namespace btfc
