// Defaults that fit the data (issue 22): lpca's default cluster count follows the texel count
// (codecs/lpca/lpca.cpp clusters_for), so on a full 81 x 81 BTF of 64 x 64 texels its bases
// no longer fill the payload; checked on the textile (../shared/data/textile_lurex_utia64).
#include <gtest/gtest.h>

#include "codecs/codec.h"
#include "core/metrics.h"
#include "formats/image_set.h"
#include "tests/test_paths.h"

using namespace btfc;

TEST(DefaultsTextile, LpcaDefaultClustersFollowTheTexelCount) {
  auto btf = read_image_set(std::string(BTFC_DATA_DIR) + "/textile_lurex_utia64");
  ASSERT_TRUE(btf.ok()) << btf.status().message();
  const Btf& b = btf.value();
  auto r = resolve_spec("lpca");
  ASSERT_TRUE(r.ok());
  Context ctx;
  auto m = r->first->encode(b, r->second, ctx);
  ASSERT_TRUE(m.ok()) << m.status().message();
  // 4096 texels / (64 x 9) = 7 clusters, recorded in the model's spec (not "clusters=0").
  EXPECT_NE((*m)->spec().find(":clusters=7:"), std::string::npos) << (*m)->spec();
  const double ratio = double(b.desc().num_values()) * 4.0 / double((*m)->payload_bytes());
  EXPECT_GE(ratio, 30.0);
  Btf out;
  ASSERT_TRUE((*m)->decode_all(out).ok());
  const Metrics e = compare_btf(b, out, false).value();
  const double bound = 0.43;  // measured 0.4164 at 126:1, 50.4 dB PSNR
  EXPECT_GE(e.rel_l2, 0.75 * bound);
  EXPECT_LE(e.rel_l2, bound);
  std::printf("[lpca default on the textile] %s: ratio %.1f, rel. L2 %.4f, PSNR %.2f dB\n", (*m)->spec().c_str(), ratio, e.rel_l2,
              e.psnr);
}
