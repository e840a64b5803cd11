// Test fmf models with chosen eigen-textures, for the BSVTF and tile-cache tests: built from
// factors directly (make_fmf_model), so any texture size costs no SVD.
#pragma once
#include <Eigen/Dense>
#include <cmath>
#include <filesystem>
#include <memory>
#include <random>
#include <string>
#include <unistd.h>

#include "codecs/fmf/fmf.h"

namespace bsvtf_test {

inline btfc::BtfDesc small_desc(int w, int h, int nl = 5, int nv = 2) {
  btfc::BtfDesc d;
  d.width = w, d.height = h;
  for (int i = 0; i < nl; ++i) d.lights.dirs.push_back(btfc::dir_from_theta_phi(0.2 * (i % 4), 1.1 * i));
  for (int i = 0; i < nv; ++i) d.views.dirs.push_back(btfc::dir_from_theta_phi(0.3 * i, 0.7 * i));
  d.lights.name = d.views.name = "custom";
  return d;
}

// Eigen-texture c: a smooth pattern plus `noise` x Gaussian texel noise, amplitude 0.6^c (the
// SVD's decay), component 0 offset to positive values like an FMF's mean component.
inline std::vector<float> eigen_textures(int w, int h, int C, double noise, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> g(0, 1);
  std::vector<float> v(size_t(w) * size_t(h) * size_t(C));
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < C; ++c) {
        const double smooth = std::sin(0.11 * (c + 1) * x + c) * std::cos(0.07 * (c + 2) * y) + 0.5 * std::sin(0.013 * (x + 2 * y));
        v[(size_t(y) * size_t(w) + size_t(x)) * size_t(C) + size_t(c)] = float(std::pow(0.6, c) * (smooth + noise * g(rng) + (c == 0 ? 2 : 0)));
      }
  return v;
}

// rows x C with orthonormal columns.
inline std::vector<float> orthonormal(size_t rows, int C, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> g(0, 1);
  Eigen::MatrixXd A(Eigen::Index(rows), C);
  for (Eigen::Index i = 0; i < A.size(); ++i) A.data()[i] = g(rng);
  Eigen::HouseholderQR<Eigen::MatrixXd> qr(A);
  Eigen::MatrixXd Q = qr.householderQ() * Eigen::MatrixXd::Identity(Eigen::Index(rows), C);
  std::vector<float> u(rows * size_t(C));
  for (size_t r = 0; r < rows; ++r)
    for (int c = 0; c < C; ++c) u[r * size_t(C) + size_t(c)] = float(Q(Eigen::Index(r), c));
  return u;
}

// color model 0 (one "rgb" block) or 11 (y, u, v blocks with C, C/2 + 1, C/2 + 1 components,
// luminance offset `offset`).
inline std::unique_ptr<btfc::Model> make_model(int w, int h, int C, double noise, unsigned seed, int color_model = 0,
                                               std::vector<float> textures = {}, float offset = 1e-5f) {
  const btfc::BtfDesc d = small_desc(w, h);
  std::vector<btfc::FmfFactors> blocks;
  const bool dfmf = color_model != 0 && color_model != 12;
  const char* names[3] = {dfmf ? "y" : "rgb", "u", "v"};
  for (int b = 0; b < (dfmf ? 3 : 1); ++b) {
    btfc::FmfFactors f;
    f.name = names[b];
    f.C = b == 0 ? C : C / 2 + 1;
    const size_t rows = dfmf ? d.num_images() : d.abrdf_size();
    f.U = orthonormal(rows, f.C, seed + 17 * unsigned(b));
    f.SxV = b == 0 && !textures.empty() ? textures : eigen_textures(w, h, f.C, noise, seed + 31 * unsigned(b));
    if (b > 0)
      for (float& v : f.SxV) v *= 0.1f;  // chroma is small
    f.S.assign(size_t(f.C), 1.0f);
    blocks.push_back(std::move(f));
  }
  auto m = btfc::make_fmf_model(d, color_model, std::move(blocks), nullptr, nullptr, false, offset);
  return m.ok() ? std::move(m).value() : nullptr;
}

inline std::filesystem::path tmp_dir() {
  return std::filesystem::temp_directory_path() / ("btfc_bsvtf_test_" + std::to_string(::getpid()));
}
// Removes this process's scratch directory at exit.
inline struct TmpCleanup {
  ~TmpCleanup() {
    std::error_code ec;
    std::filesystem::remove_all(tmp_dir(), ec);
  }
} tmp_cleanup;

inline std::string tmp_path(const std::string& name) {
  std::filesystem::create_directories(tmp_dir());
  return (tmp_dir() / name).string();
}

}  // namespace bsvtf_test
