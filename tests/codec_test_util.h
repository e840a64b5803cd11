// Helpers the codec tests share: encoding by spec string, the --max-bytes search check.
#pragma once
#include <gtest/gtest.h>

#include <cstdint>
#include <memory>
#include <string>

#include "codecs/codec.h"
#include "codecs/target.h"
#include "core/metrics.h"

namespace btfc::test {

// Encodes `b` with the registry's codec for `spec` ("fmf:rank=8", parameters as the CLI takes
// them) and Context::seed = `seed` (the default Context's). An unknown spec or a failed encode
// fails the test and returns nullptr.
inline std::unique_ptr<Model> encode_spec(const Btf& b, const std::string& spec, uint64_t seed = 1) {
  auto r = resolve_spec(spec);
  EXPECT_TRUE(r.ok()) << spec << ": " << r.status().message();
  if (!r.ok()) return nullptr;
  Context ctx;
  ctx.seed = seed;
  auto m = r->first->encode(b, r->second, ctx);
  EXPECT_TRUE(m.ok()) << spec << ": " << m.status().message();
  return m.ok() ? std::move(m).value() : nullptr;
}

// --max-bytes over a codec's settings (its budget_variants: half and precision=q at bits 4, 6, 8):
// the search from `spec` fits `budget` and chose a precision=q setting; the search from
// `half_spec` (the precision fixed to half) fits too and keeps half; the full search is at least as
// good as the half-only one.
inline void expect_budget_search_beats_half(const Btf& b, const std::string& spec, const std::string& half_spec, double budget) {
  Context ctx;
  auto any = choose_for_target(b, spec, Target{Target::Kind::max_bytes, budget}, ctx);
  ASSERT_TRUE(any.ok()) << spec << ": " << any.status().message();
  EXPECT_LE(double(any->model->payload_bytes()), budget);
  EXPECT_NE(any->variants.find("precision=q"), std::string::npos) << any->variants;
  auto half = choose_for_target(b, half_spec, Target{Target::Kind::max_bytes, budget}, ctx);
  ASSERT_TRUE(half.ok()) << half_spec << ": " << half.status().message();
  EXPECT_LE(double(half->model->payload_bytes()), budget);
  EXPECT_NE(half->model->spec().find("precision=half"), std::string::npos) << half->model->spec();
  Btf out;
  ASSERT_TRUE(half->model->decode_all(out).ok());
  EXPECT_GE(any->psnr, compare_btf(b, out, false).value().psnr) << any->variants;
}

}  // namespace btfc::test
