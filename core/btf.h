// The BTF data model (spec section 2).
//
// A BTF is rho(x, w_l, w_v): per texel (width x height), per light direction (lights) and view
// direction (views), `channels` linear float values (RGB; HDR allowed). Light and view
// direction sets are stored separately and never assumed equal; a partial measurement
// (e.g. one view x 81 lights) is just a BTF with a one-direction view set.
//
// Memory layout (pinned; codecs and the container rely on it): texel-major, float32,
//   value(x, y, l, v, c) = data[texel * abrdf_size + row],
//   texel = x + width * y,   row = c + channels * (l + num_lights * v).
// So each texel's apparent BRDF (ABRDF) is contiguous, and the buffer *is* the BTF matrix B
// of seed 000 section 4 (rows = (view, light, colour), columns = texels) stored column-major:
// the SVD path maps it into Eigen without a copy (core/btf_matrix.h). The image stack (one
// W x H image per (light, view)) is a strided view of the same buffer (ImageView below).
// Row order matches Bonn FMF files (formats.md 2.2: row = c + nC * (l + nL * v)).
#pragma once
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "core/limits.h"
#include "core/status.h"

namespace btfc {

struct Vec3 {
  float x = 0, y = 0, z = 1;
};

// theta = polar angle from +z, phi = atan2(y, x); radians.
Vec3 dir_from_theta_phi(double theta, double phi);
void dir_to_theta_phi(const Vec3& d, double& theta, double& phi);

struct DirectionSet {
  std::string name;       // "ubo2003" (81), "ubo2014" (151), or "custom"
  std::vector<Vec3> dirs; // unit vectors in the sample's tangent frame, z = normal

  size_t size() const { return dirs.size(); }
  // The UBO2003 / UTIA 81-direction sampling: rings theta 0,15,..,75 deg with 1,6,12,18,20,24
  // directions, ring ascending then phi ascending (formats.md 2.1).
  static DirectionSet ubo2003();
  // The Bonn UBO2014 Dome 1 sampling, 151 directions (formats.md 2.2).
  static DirectionSet ubo2014();
  // A single direction (e.g. the view of a one-view slice).
  static DirectionSet single(const Vec3& d, std::string name = "custom");
  // Finds the index of `d` within `tol_rad` radians, or -1.
  int find(const Vec3& d, double tol_rad = 1e-3) const;
  // Names the set "ubo2003"/"ubo2014" if it equals one of them within 0.5 degrees, else "custom".
  void identify();
};

struct BtfDesc {
  int width = 0, height = 0;
  int channels = 3;
  DirectionSet lights, views;
  bool hdr = false;  // values are linear float from an HDR source (PSNR peak rule uses the data max)

  size_t num_texels() const { return size_t(width) * size_t(height); }
  size_t num_lights() const { return lights.size(); }
  size_t num_views() const { return views.size(); }
  size_t num_images() const { return num_lights() * num_views(); }
  size_t abrdf_size() const { return num_images() * size_t(channels); }  // rows of B
  size_t num_values() const { return abrdf_size() * num_texels(); }
  size_t row(size_t l, size_t v, size_t c) const { return c + size_t(channels) * (l + num_lights() * v); }
  // Rejects empty or absurd shapes and products that overflow (each axis <= 2^20, total <= 2^40).
  Status validate() const;
  std::string summary() const;  // "256x256 texels, 81 lights x 81 views, 3 channels"
};

// A strided, non-owning view of one (light, view) image of a texel-major buffer.
struct ImageView {
  const float* base = nullptr;  // value of texel 0 channel 0 of this image
  size_t texel_stride = 0;      // floats between neighbouring texels (= abrdf_size)
  int width = 0, height = 0, channels = 0;
  float at(int x, int y, int c) const { return base[(size_t(x) + size_t(width) * size_t(y)) * texel_stride + size_t(c)]; }
};

// Float storage for large BTFs: 2 MiB-aligned, transparent huge pages requested, first touched
// in parallel. On the VMs btfc runs on, first-touch page faults of 4 KiB pages ran at
// 160-320 MB/s (5.2 GB took 19-45 s); huge pages and a parallel touch are 3-5x faster.
class FloatBuffer {
 public:
  FloatBuffer() = default;
  explicit FloatBuffer(size_t n);  // zero-filled; throws std::bad_alloc like std::vector
  FloatBuffer(const FloatBuffer& o);
  FloatBuffer& operator=(const FloatBuffer& o);
  FloatBuffer(FloatBuffer&&) noexcept = default;
  FloatBuffer& operator=(FloatBuffer&&) noexcept = default;
  float* data() { return m_p.get(); }
  const float* data() const { return m_p.get(); }
  size_t size() const { return m_n; }
  float& operator[](size_t i) { return m_p.get()[i]; }
  float operator[](size_t i) const { return m_p.get()[i]; }

 private:
  struct Free {
    void operator()(float* p) const;
  };
  std::unique_ptr<float[], Free> m_p;
  size_t m_n = 0;
};

class Btf {
 public:
  Btf() = default;
  // Allocates zero-filled storage; fails (without allocating) when desc is invalid or the
  // buffer would exceed `max_bytes` (default: the process memory limit, core/limits.h).
  static Result<Btf> create(const BtfDesc& desc, size_t max_bytes = memory_limit());

  const BtfDesc& desc() const { return m_desc; }
  float* data() { return m_data.data(); }
  const float* data() const { return m_data.data(); }
  size_t size() const { return m_data.size(); }

  float& at(size_t x, size_t y, size_t l, size_t v, size_t c) {
    return m_data[(x + size_t(m_desc.width) * y) * m_desc.abrdf_size() + m_desc.row(l, v, c)];
  }
  float at(size_t x, size_t y, size_t l, size_t v, size_t c) const {
    return m_data[(x + size_t(m_desc.width) * y) * m_desc.abrdf_size() + m_desc.row(l, v, c)];
  }
  // The ABRDF of one texel: abrdf_size() contiguous values.
  const float* abrdf(size_t texel) const { return m_data.data() + texel * m_desc.abrdf_size(); }
  float* abrdf(size_t texel) { return m_data.data() + texel * m_desc.abrdf_size(); }
  ImageView image(size_t l, size_t v) const;

  // Gives the storage a new description with the same value count (block-wise decoding reuses
  // one buffer); the values are left as they are.
  void reshape(const BtfDesc& d) { m_desc = d; }

  // First non-finite value as an error naming (x, y, light, view, channel), else ok.
  Status check_finite(const std::string& what) const;

 private:
  BtfDesc m_desc;
  FloatBuffer m_data;
};

// Index of the first non-finite value among v[0, n), or n when all are finite. Vectorized and
// parallel over blocks: multi-GB inputs are checked on every read.
size_t find_non_finite(const float* v, size_t n);

// The largest |v[i]| of v[0, n) (finite values; 0 for none). Parallel over blocks, as above.
float max_abs(const float* v, size_t n);

// Codecs whose fits sum squares of the values in float (lpca's clustering, mlvq's search) meet
// overflow past ~1e17 and underflow below ~1e-19. Such a codec fits a copy scaled by 2^k (exact)
// when the largest |value| lies outside [2^-32, 2^32], and scales its model back: k brings that
// value into [1, 2); 0 inside the range, for all-zero data and for a non-finite peak.
int fit_scale_exponent(float peak);
// A copy of btf with every value times 2^k (exact for normal results).
Result<Btf> scaled_copy(const Btf& btf, int k);
// d[i] = s[i] x 2^k for i in [0, n) (d may be s), in two power-of-two factors: 2^k alone passes
// the float range for |k| > 127 (subnormal peaks). Exact for normal results. Used by scaled_copy
// and by the codecs that scale their fitted model back.
void scale_by_pow2(const float* s, float* d, size_t n, int k);

}  // namespace btfc
