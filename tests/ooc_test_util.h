// Helpers of the out-of-core tests (ooc_test.cpp, ooc_dfmf_test.cpp): a synthetic BTF, an
// in-memory chunk source, processes simulated by threads, reconstruction errors.
#pragma once
#include <gtest/gtest.h>
#include <unistd.h>

#include <Eigen/Dense>
#include <cmath>
#include <cstring>

#include "codecs/codec.h"
#include "codecs/fmf/ooc_svd.h"
#include "core/synth.h"
#include "formats/bonn/bdi_work.h"
#include "tests/thread_group.h"

namespace btfc::ooc_test {

inline std::string tmp_path(const std::string& name) { return ::testing::TempDir() + "/ooc_" + std::to_string(::getpid()) + "_" + name; }

// A synthetic BTF: 81 lights, 2 views, RGB -> 486 rows.
inline Btf synth(int w, int h, float scale = 1.0f) {
  SynthOptions o;
  o.width = w, o.height = h, o.scale = scale;
  o.views = DirectionSet::single(dir_from_theta_phi(0.5, 1.0));
  o.views.dirs.push_back(dir_from_theta_phi(0.9, 2.0));
  return synthesize_btf(o).value();
}

inline Status write_bdi(const Btf& b, const std::string& path, uint32_t lines, float scale = 1.0f) {
  BTFC_ASSIGN_OR_RETURN(auto w, BdiWriter::create(path, b.desc(), lines, scale, "<btfc_work scale=\"" + std::to_string(scale) + "\"/>"));
  BTFC_RETURN_IF_ERROR(w->write_texels(0, b.desc().num_texels(), b.data()));
  return w->finish();
}

// The whole matrix as chunks of `per` texels, straight from memory (no half rounding).
class MemorySource final : public ChunkSource {
 public:
  MemorySource(const Btf& b, size_t per) : m_b(b), m_per(per) {}
  size_t rows() const override { return m_b.desc().abrdf_size(); }
  size_t num_chunks() const override { return (m_b.desc().num_texels() + m_per - 1) / m_per; }
  size_t chunk_first(size_t c) const override { return c * m_per; }
  size_t chunk_count(size_t c) const override { return std::min(m_per, m_b.desc().num_texels() - c * m_per); }
  size_t raw_bytes(size_t c) const override { return chunk_count(c) * rows() * 4; }
  Status read(size_t c, void* raw) const override {
    if (fail_chunk == c) return io_error("cannot read chunk " + std::to_string(c) + " (injected)");
    std::memcpy(raw, m_b.abrdf(chunk_first(c)), raw_bytes(c));
    return {};
  }
  Status decode(size_t c, const void* raw, float* dst) const override {
    std::memcpy(dst, raw, raw_bytes(c));
    return {};
  }
  // Zero-copy chunks straight from the Btf (the mapped path of the SVDs and of DfmfChannelSource).
  bool mappable() const override { return mapped; }
  Result<const float*> map(size_t c) const override {
    if (fail_chunk == c) return io_error("cannot map chunk " + std::to_string(c) + " (injected)");
    return m_b.abrdf(chunk_first(c));
  }
  size_t fail_chunk = size_t(-1);
  bool mapped = false;

 private:
  const Btf& m_b;
  size_t m_per;
};

// P "processes" as threads (tests/thread_group.h).
using test::run_group;

// ||B - U SxV^T||_F / ||B||_F.
inline double actual_error(const Btf& b, const SvdResult& r) {
  const size_t m = b.desc().abrdf_size(), n = b.desc().num_texels();
  Eigen::Map<const Eigen::MatrixXf> B(b.data(), Eigen::Index(m), Eigen::Index(n));
  Eigen::MatrixXd R = B.cast<double>() - r.U.cast<double>() * r.SxV.cast<double>().transpose();
  return R.norm() / B.cast<double>().norm();
}

// Relative L2 error of a model's decoded BTF against `b`.
inline double model_error(const Btf& b, const Model& m) {
  Btf out;
  EXPECT_TRUE(m.decode_all(out).ok());
  double se = 0, sr = 0;
  for (size_t i = 0; i < b.size(); ++i) se += std::pow(double(out.data()[i]) - b.data()[i], 2), sr += std::pow(double(b.data()[i]), 2);
  return std::sqrt(se / sr);
}

}  // namespace btfc::ooc_test
