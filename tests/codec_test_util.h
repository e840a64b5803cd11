// Encoding by spec string for the codec tests: the one helper the test files share.
#pragma once
#include <gtest/gtest.h>

#include <cstdint>
#include <memory>
#include <string>

#include "codecs/codec.h"

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

}  // namespace btfc::test
