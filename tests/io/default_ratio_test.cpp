// Issue 22: "every codec's default gives a ratio of at least 30 on any full BTF of 48 x 48 texels
// or more". Every registered codec at its default spec on full 81 x 81 direction BTFs of the
// kinds users hold: smooth synthetic (48 x 48 and 64 x 64), HDR-scaled synthetic with
// measurement noise (core/synth.h `noise`), and a 48 x 48 crop of the textile
// (../shared/data/textile_lurex_utia64: rendered HDR, Monte Carlo noise). The ratio is against
// float32 raw data (4 bytes per value), as `btfc bench` reports it. The bound is the issue's
// requirement (one-sided by nature: a codec may compress more); the quality at those defaults
// has its own two-sided bounds in the codecs' tests.
#include <gtest/gtest.h>

#include <cstdio>

#include "codecs/codec.h"
#include "core/synth.h"
#include "formats/image_set.h"
#include "tests/test_paths.h"

using namespace btfc;

namespace {

Btf synth(int n, float scale, float noise) {
  SynthOptions o;
  o.width = o.height = n;
  o.scale = scale, o.noise = noise;
  o.seed = 3;
  auto b = synthesize_btf(o);
  EXPECT_TRUE(b.ok()) << b.status().message();
  return b.ok() ? std::move(b).value() : Btf();
}

Btf textile_crop(int x0, int y0, int n) {
  auto full = read_image_set(std::string(BTFC_DATA_DIR) + "/textile_lurex_utia64");
  EXPECT_TRUE(full.ok()) << full.status().message();
  if (!full.ok()) return Btf();
  BtfDesc d = full->desc();
  d.width = d.height = n;
  auto c = Btf::create(d);
  EXPECT_TRUE(c.ok());
  for (int y = 0; y < n; ++y)
    for (int x = 0; x < n; ++x)
      std::copy_n(full->abrdf(size_t(x0 + x) + size_t(full->desc().width) * size_t(y0 + y)), d.abrdf_size(), c->abrdf(size_t(x + n * y)));
  return std::move(c).value();
}

void expect_default_ratios(const Btf& b, const char* what) {
  ASSERT_GT(b.size(), 0u) << what;
  for (const Codec* codec : all_codecs()) {
    auto r = resolve_spec(codec->name());
    ASSERT_TRUE(r.ok()) << r.status().message();
    Context ctx;
    auto m = codec->encode(b, r->second, ctx);
    ASSERT_TRUE(m.ok()) << codec->name() << " on " << what << ": " << m.status().message();
    const double ratio = double(b.desc().num_values()) * 4.0 / double((*m)->payload_bytes());
    std::printf("[default ratio] %s on %s: %s 1:%.0f\n", codec->name(), what, (*m)->spec().c_str(), ratio);
    EXPECT_GE(ratio, 30.0) << codec->name() << " default on " << what;
  }
}

}  // namespace

TEST(DefaultRatio, Synthetic48) { expect_default_ratios(synth(48, 1, 0), "synthetic 48 x 48"); }
TEST(DefaultRatio, Synthetic64) { expect_default_ratios(synth(64, 1, 0), "synthetic 64 x 64"); }
TEST(DefaultRatio, SyntheticHdrNoisy48) { expect_default_ratios(synth(48, 1000, 0.05f), "synthetic 48 x 48 x 1000, 5 % noise"); }
TEST(DefaultRatio, TextileCrop48) { expect_default_ratios(textile_crop(8, 8, 48), "textile crop 48 x 48"); }
