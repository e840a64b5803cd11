// The lpca Model (internal to codecs/lpca/: lpca.cpp builds and loads it, relight.cpp reads it).
// Users go through Model (codecs/codec.h) and the functions of lpca.h.
#pragma once
#include <Eigen/Core>
#include <mutex>
#include <vector>

#include "codecs/codec.h"
#include "codecs/lpca/clustering.h"
#include "core/interp.h"

namespace btfc::lpca {

struct Config {
  int components = 8;  // c per cluster
  bool half = true;    // storage of table and weights
  int bits = 0;        // precision=q: > 0, the bit depth of the equal-error steps (lpca.h)
  int sh_order = 5;    // n: n*n SH coefficients per (row of the table, view, channel)
};

class LpcaModel final : public Model {
 public:
  // table: [K*(c+1)] x abrdf_size (per cluster: mean, then c eigen-BRDFs), dequantized;
  // weights: [texels] x c, dequantized; mean_scale [K] and weight_scale [K*c] are the storage
  // scales (all 1 for float storage).
  LpcaModel(BtfDesc desc, std::string spec, Config cfg, std::vector<uint32_t> cluster_of, MatrixXfR table,
            MatrixXfR weights, std::vector<float> mean_scale, std::vector<float> weight_scale);

  const BtfDesc& desc() const override { return m_desc; }
  const std::string& spec() const override { return m_spec; }
  Status decode(const DecodeRequest& req, Btf& out) const override;
  void eval(int x, int y, int light, int view, float* out) const override;
  Status eval_dir(int x, int y, const Vec3& wl, const Vec3& wv, float* out) const override;
  // eval_dir's values (to float round-off) without its per-call overheads: lpca.cpp says why.
  Status eval_batch(std::span<const EvalQuery> q, float* out) const override;
  Result<std::vector<Tensor>> gpu_tensors() const override;
  Status attach_environment(const EnvironmentSH& env) override;  // relight.cpp
  // The PRT path of seed 002 (relight.cpp): equals Model::relight's quadrature for environments
  // of at most sh_order bands, at the cost of one dot product per texel and component.
  Result<std::vector<float>> relight(const EnvironmentSH& env, const Vec3& view_dir) const override;
  Status save(ContainerWriter& w) const override;
  uint64_t payload_bytes() const override;
  ModelStats stats() const override { return m_stats; }

  ModelStats& mutable_stats() { return m_stats; }
  const Config& config() const { return m_cfg; }
  int clusters() const { return m_clusters; }
  int components() const { return m_cfg.components; }
  const std::vector<uint32_t>& cluster_of() const { return m_cluster_of; }
  const MatrixXfR& table() const { return m_table; }
  const MatrixXfR& weights() const { return m_weights; }
  // Quadrature weights of the light directions (sh::hemisphere_cell_weights).
  const std::vector<double>& light_weights() const { return m_light_w; }
  // SH projection over light directions of every table row, per view and channel:
  // [K*(c+1)][views][channels][n*n] (seed 002 section 4.3: e^v_{j,k}).
  const std::vector<float>& eigen_sh() const { return m_eigen_sh; }
  const DirectionInterpolator& view_interp() const { return m_view_interp; }
  // PRT tensors for a fixed lighting (attach_environment in lpca.h); returned by gpu_tensors().
  void set_prt(std::vector<Tensor> t) { m_prt = std::move(t); }
  // precision=q: the zq tensors cluster, table, weights as saved (their values are the model's).
  void set_coded(std::vector<Tensor> t) { m_coded = std::move(t); }

 private:
  BtfDesc m_desc;
  std::string m_spec;
  Config m_cfg;
  int m_clusters = 0;
  std::vector<uint32_t> m_cluster_of;
  MatrixXfR m_table, m_weights;
  std::vector<float> m_mean_scale, m_weight_scale;
  std::vector<double> m_light_w;
  std::vector<float> m_eigen_sh;
  DirectionInterpolator m_light_interp, m_view_interp;
  std::vector<Tensor> m_prt;
  std::vector<Tensor> m_coded;
  ModelStats m_stats;
  // eval()'s copy of the table, made on first use: per cluster k and table column (row of the
  // ABRDF), its c + 1 values (mean, eigen-BRDFs) adjacent, [(k * abrdf_size + col) * (c + 1) + i],
  // so a (light, view) pair's channels are one run of 3 (c + 1) floats. In m_table they are
  // abrdf_size floats apart (one cache line per value: 27 (c + 1) scattered lines per
  // interpolated query); the decode's GEMM keeps m_table's layout.
  const float* eval_table() const;
  mutable std::once_flag m_eval_once;
  mutable std::vector<float> m_eval_table;
};

}  // namespace btfc::lpca
