// Shared helpers of the codec exporter tests (export_codecs_test.cpp, export_lpca_test.cpp):
// small synthetic BTFs, encoding by spec string, bundles, shader queries at texel centres and at
// direction-map cell centres, and the tolerances.
#pragma once
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "codecs/codec.h"
#include "core/synth.h"
#include "formats/gpu/export.h"
#include "tests/codec_test_util.h"

namespace btfc::export_test {

using namespace btfc::gpu;

constexpr double k_half_rel = 1.0 / 2048;  // half rounding, normal numbers: |x - h(x)| <= 2^-11 |x|
constexpr double k_half_abs = 1.0 / 33554432;  // subnormal halves: 2^-25 absolute

inline DirectionSet some_views() {
  DirectionSet all = DirectionSet::ubo2003(), s;
  for (int i : {0, 7, 14, 22, 31, 45, 60, 75}) s.dirs.push_back(all.dirs[size_t(i)]);
  s.name = "custom";
  return s;
}

inline Btf synth(int w, int h) {
  SynthOptions o;
  o.width = w, o.height = h, o.views = some_views();
  return synthesize_btf(o).value();
}

inline std::unique_ptr<Model> encode(const Codec& codec, const Btf& b, const std::string& spec) {
  auto s = parse_spec_string(spec);
  EXPECT_TRUE(s.ok());
  auto p = bind_params(*s, codec.params());
  EXPECT_TRUE(p.ok()) << p.status().message();
  Context ctx;
  auto m = codec.encode(b, *p, ctx);
  EXPECT_TRUE(m.ok()) << m.status().message();
  return m.ok() ? std::move(m).value() : nullptr;
}

using test::encode_spec;  // tests/codec_test_util.h

// A synthetic BTF on the full UBO2003 light and view sets, values scaled by `scale` (HDR tests).
inline Btf synth_ubo(int w, int h, float scale = 1) {
  SynthOptions o;
  o.width = w, o.height = h, o.scale = scale;
  return synthesize_btf(o).value();
}

inline double rms_of(const Btf& b) {
  double s = 0;
  for (size_t i = 0; i < b.size(); ++i) s += double(b.data()[i]) * b.data()[i];
  return std::sqrt(s / double(b.size()));
}

inline ExportBundle bundle(const Model& m, bool half, int dir_n = 32) {
  ExportOptions o;
  o.half = half, o.direction_map = dir_n;
  auto b = build_export(m, o);
  EXPECT_TRUE(b.ok()) << b.status().message();
  return b.ok() ? std::move(b).value() : ExportBundle{};
}

inline ShaderQuery at_texel(const BtfDesc& d, int x, int y) {
  ShaderQuery q;
  q.u = (float(x) + 0.5f) / float(d.width), q.v = (float(y) + 0.5f) / float(d.height);
  return q;
}

// The direction of a parabolic map cell's centre (as direction_maps and the LUT compute it);
// false for cells whose centre lies outside the unit disc (they hold the rim's value).
inline bool cell_centre(int cx, int cy, int n, Vec3& d) {
  const double px = (cx + 0.5) / n * 2 - 1, py = (cy + 0.5) / n * 2 - 1, r2 = px * px + py * py;
  if (r2 >= 1) return false;
  const double s = 1 / (1 + r2);
  d = {float(2 * px * s), float(2 * py * s), float((1 - r2) * s)};
  return true;
}

inline std::vector<Vec3> random_cell_centres(int n, int count, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> u(0, n - 1);
  std::vector<Vec3> out;
  Vec3 d;
  while (int(out.size()) < count)
    if (cell_centre(u(rng), u(rng), n, d) && d.z > 0.2f) out.push_back(d);
  return out;
}

inline double float_tol(const float* ref) { return 2e-6 * (1 + std::abs(ref[0]) + std::abs(ref[1]) + std::abs(ref[2])); }

struct Errors {
  double max_err = 0, max_ratio = 0;
  bool within = true;
};


}  // namespace btfc::export_test
