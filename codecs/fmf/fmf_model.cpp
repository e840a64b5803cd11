// FmfModel: decode, evaluation and save (fmf_model.h; the paper and the tensors: fmf.h).
#include <Imath/half.h>

#include <algorithm>
#include <atomic>
#include <future>
#include <system_error>

#include "codecs/fmf/fmf_model.h"
#include "core/cl_runtime.h"
#include "core/fixed_product.h"

namespace btfc::fmf {

fmf_cl::PackedFactors FmfModel::packed() const {
  fmf_cl::PackedFactors f;
  f.mode = m_cfg.dfmf ? BTFC_FMF_DFMF : BTFC_FMF_RGB;
  f.blocks = int(m_blocks.size());
  for (const Block& b : m_blocks) f.C = std::max(f.C, int(b.U.cols())), f.block_C.push_back(int(b.U.cols()));
  f.rows_per_block = int(m_blocks[0].U.rows());
  f.texels = int(m_desc.num_texels());
  f.nL = int(m_desc.num_lights());
  f.nV = int(m_desc.num_views());
  f.eps = m_cfg.dfmf ? m_cfg.offset : BTFC_DRR_EPS;
  // Blocks with fewer components (dfmf chroma) are zero-padded to the common C.
  f.U.assign(size_t(f.blocks) * f.rows_per_block * f.C, 0.0f);
  f.SxV.assign(size_t(f.blocks) * f.texels * f.C, 0.0f);
  for (int k = 0; k < f.blocks; ++k) {
    const Block& b = m_blocks[size_t(k)];
    for (Index r = 0; r < b.U.rows(); ++r)
      for (Index c = 0; c < b.U.cols(); ++c) f.U[(size_t(k) * f.rows_per_block + size_t(r)) * f.C + size_t(c)] = b.U(r, c);
    for (Index t = 0; t < b.SxV.rows(); ++t)
      for (Index c = 0; c < b.SxV.cols(); ++c) f.SxV[(size_t(k) * f.texels + size_t(t)) * f.C + size_t(c)] = b.SxV(t, c);
  }
  return f;
}

Result<std::shared_ptr<fmf_cl::DeviceFactors>> FmfModel::device_factors() const {
  std::lock_guard<std::mutex> lock(m_cl_mutex);
  if (!m_cl) {
    BTFC_ASSIGN_OR_RETURN(m_cl, fmf_cl::DeviceFactors::upload(packed()));
  }
  return m_cl;
}

Status FmfModel::decode_cl(const ResolvedRequest& rr, Btf& out) const {
  BTFC_ASSIGN_OR_RETURN(auto dev, device_factors());
  std::vector<int> texels(rr.desc.num_texels());
  for (size_t i = 0; i < texels.size(); ++i)
    texels[i] = int((rr.x0 + i % size_t(rr.desc.width)) + size_t(m_desc.width) * (rr.y0 + i / size_t(rr.desc.width)));
  return dev->decode(texels, rr.lights, rr.views, out.data());
}

Status FmfModel::eval_batch(std::span<const EvalQuery> q, float* out) const {
  if (m_cfg.color_model >= 0 || (m_cfg.dfmf && m_desc.channels != 3)) return Model::eval_batch(q, out);
  BTFC_RETURN_IF_ERROR(check_eval_queries(m_desc, q));
  // On a CPU, the C++ paths (rgb: the sorted blocks of fmf_eval.h; dfmf: fmf_eval_dfmf.cpp). They
  // are also faster than the OpenCL kernels on PoCL's CPU device (docs/benchmarks.md), so OpenCL
  // serves eval_batch only on a GPU or when asked for (--device cl).
  const ocl::DeviceChoice dc = ocl::device_choice();
  bool gpu = false;
  if (dc == ocl::DeviceChoice::automatic && ocl::use_opencl()) {
    auto rt = ocl::Runtime::get();
    gpu = rt.ok() && rt.value()->info().type == "gpu";
  }
  const bool cpu = dc != ocl::DeviceChoice::cl && !gpu;
  if (m_cfg.dfmf && cpu) return eval_batch_dfmf_cpu(q, out);
  if (!m_cfg.dfmf && cpu && m_desc.num_lights() <= 65535 && m_desc.num_views() <= 65535)  // fmf_eval.cpp packs indices in 16 bits
    return eval_batch_cpu(q, out);
  if (m_desc.channels != 3 || !ocl::use_opencl()) return Model::eval_batch(q, out);
  // Convert to the kernel's query layout: directions become 3 + 3 (index, weight) pairs (the
  // renderer's index / weight textures).
  std::vector<btfc_fmf_query> kq(q.size());
  const size_t qb = 4096;
#pragma omp parallel for schedule(static)
  for (size_t b0 = 0; b0 < q.size(); b0 += qb) to_weighted(q.data() + b0, std::min(qb, q.size() - b0), kq.data() + b0);
  // Runs of queries sharing a direction pair go through the blended-rows kernel (fmf_cl.h).
  Status s;
  auto dev = device_factors();
  s = dev.ok() ? dev.value()->eval_batch(kq, out) : dev.status();
  if (s.ok()) return s;
  if (!ocl::fall_back_after(s)) return s;
  return Model::eval_batch(q, out);
}

Status FmfModel::decode(const DecodeRequest& req, Btf& out) const {
  BTFC_ASSIGN_OR_RETURN(ResolvedRequest rr, resolve_request(m_desc, req));
  BTFC_RETURN_IF_ERROR(prepare_output(rr.desc, out));
  if (m_desc.channels == 3 && m_cfg.color_model < 0 && ocl::use_opencl()) {
    Status s = decode_cl(rr, out);
    if (s.ok() || !ocl::fall_back_after(s)) return s;
  }
  // The C++ reference (and the CPU path): per texel block, one Eigen GEMM per factorized block.
  const Index nl = Index(rr.lights.size()), nv = Index(rr.views.size());
  const Index w = rr.desc.width, n = Index(rr.desc.num_texels()), m = Index(rr.desc.abrdf_size());
  const int nc = m_desc.channels;
  // Gather the U rows of the requested directions, in the output's row order.
  const int nblocks = int(m_blocks.size());
  // Stored transposed (components x rows): fixed_order_product's right operand.
  std::vector<MatrixXfR> Usub(nblocks);
  const Index rows_per_block = m_cfg.dfmf ? nl * nv : m;
  for (int k = 0; k < nblocks; ++k) {
    Usub[k].resize(rows_per_block, m_blocks[k].U.cols());
    for (Index v = 0; v < nv; ++v)
      for (Index l = 0; l < nl; ++l) {
        if (m_cfg.dfmf) {
          Usub[k].row(l + nl * v) = m_blocks[k].U.row(rr.lights[l] + Index(m_desc.num_lights()) * rr.views[v]);
        } else {
          for (int c = 0; c < nc; ++c)
            Usub[k].row(c + nc * (l + nl * v)) = m_blocks[k].U.row(Index(m_desc.row(rr.lights[l], rr.views[v], c)));
        }
      }
    Usub[k] = Usub[k].transpose().eval();
  }
  // Texel blocks bound the temporary memory; each block is one GEMM per factorized channel.
  // Texel tiles of at most ~16 M temporary floats per channel (64 MB), and buffers reused across
  // tiles: fresh memory is slow to fault in on the VMs btfc runs on, and a 4096-texel tile of a
  // UBO2014 per-channel model would need 1.1 GB of temporaries.
  const Index tb = std::clamp<Index>((Index(16) << 20) / std::max<Index>(1, rows_per_block), 16, 4096);
  std::vector<MatrixXfR> sx(nblocks);
  MatrixXfR ch[3];
  for (Index t0 = 0; t0 < n; t0 += tb) {
    const Index nb = std::min(tb, n - t0);
    for (int k = 0; k < nblocks; ++k) {
      sx[k].resize(nb, m_blocks[k].SxV.cols());
      for (Index i = 0; i < nb; ++i) {
        const Index t = t0 + i, sx_t = (rr.x0 + t % w) + Index(m_desc.width) * (rr.y0 + t / w);
        sx[k].row(i) = m_blocks[k].SxV.row(sx_t);
      }
    }
    Eigen::Map<MatrixXfR> dst(out.data() + size_t(t0) * size_t(m), nb, m);
    // fixed_order_product, not a GEMM: a texel's values must not depend on the tile it falls
    // in, so that band-wise (streamed) decodes equal whole decodes bit for bit.
    auto product = [&](int k, float* to) {
      fixed_order_product(sx[k].data(), size_t(nb), size_t(sx[k].cols()), size_t(sx[k].cols()), Usub[k].data(),
                          size_t(rows_per_block), to, size_t(rows_per_block));
    };
    if (!m_cfg.dfmf) {
      product(0, dst.data());
      if (m_cfg.color_model == 12) dst = (dst.array().exp() - k_drr_eps).matrix();  // Bonn FMF dynamic range reduction
      continue;
    }
    for (int k = 0; k < 3; ++k) {
      ch[k].resize(nb, rows_per_block);  // no reallocation when the size is unchanged
      product(k, ch[k].data());
    }
#pragma omp parallel for schedule(static)
    for (Index i = 0; i < nb; ++i)
      for (Index r = 0; r < rows_per_block; ++r) {
        const float in[3] = {ch[0](i, r), ch[1](i, r), ch[2](i, r)};
        undecorrelate(in, &dst(i, 3 * r));
      }
  }
  return {};
}

Status FmfModel::quantize_block(Block& b) const {
  fmf::QuantConfig qc = m_cfg.quant;
  qc.centred = m_cfg.dfmf && b.name == "y";  // log luminance (fmf_quant.h)
  fmf::QuantizedFactors q = fmf::quantize_factors(b.name, b.U, b.SxV, qc, m_desc.width, m_desc.height);
  b.U = std::move(q.U), b.SxV = std::move(q.SxV), b.coded = std::move(q.coded);
  b.scale = Eigen::VectorXf::Ones(b.SxV.cols());
  return q.status;
}

void FmfModel::quantize_blocks() {
  // Each block's SxV is one zstd call (level 19; single-threaded below 8 MiB of planes, two jobs
  // above, core/quant.h; its U, a few rows, runs beside it): most of a q encode's time.
  // color=dfmf's three blocks go to two threads, each taking the next block in order (y on one,
  // u then v on the other; the UBO2003 slice's 256 x 256 texels at rank 64: encode 11.4 -> 5.8-6.4
  // s), at most two eigen-texture coders (<= 81 MB each) alive. The same bytes either way.
  std::vector<Status> status(m_blocks.size());
  std::atomic<size_t> next{0};
  auto work = [&] {
    for (size_t i; (i = next++) < m_blocks.size();)
      if (m_blocks[i].coded.empty()) status[i] = quantize_block(m_blocks[i]);
  };
  const auto todo = std::count_if(m_blocks.begin(), m_blocks.end(), [](const Block& b) { return b.coded.empty(); });
  std::future<void> other;
  if (todo > 1) {  // not for rgb's one block, nor for a loaded model's coded ones
    try {
      other = std::async(std::launch::async, work);
    } catch (const std::system_error&) {  // no thread to be had: this one does them all
    }
  }
  work();
  if (other.valid()) other.get();
  for (const Status& st : status)
    if (!st.ok()) {
      m_quant_status = st;
      break;
    }
}

Status FmfModel::save(ContainerWriter& w) const {
  BTFC_RETURN_IF_ERROR(m_quant_status);
  if (m_cfg.color_model >= 0)
    return unsupported("fmf: a model with Bonn colour model " + std::to_string(m_cfg.color_model) +
                       " cannot be saved as .btfc (only 11 = color=dfmf and 0 = color=rgb); decompress and re-compress it instead");
  for (const Block& b : m_blocks) {
    const uint64_t rows = uint64_t(b.U.rows()), cols = uint64_t(b.U.cols()), texels = uint64_t(b.SxV.rows());
    if (!b.coded.empty()) {  // precision=q: the zq tensors made when quantizing
      for (const Tensor& t : b.coded) w.add_tensor(t);
      w.add_tensor(Tensor::from_f32("scale." + b.name, {cols}, b.scale.data()));
      w.add_tensor(Tensor::from_f32("S." + b.name, {cols}, b.S.data()));
      continue;
    }
    MatrixXfR sxv_scaled = b.SxV * b.scale.cwiseInverse().asDiagonal();
    auto put = [&](const std::string& name, const MatrixXfR& M, std::vector<uint64_t> shape) {
      if (!m_cfg.half) {
        w.add_tensor(Tensor::from_f32(name, std::move(shape), M.data()));
        return;
      }
      Tensor t;
      t.name = name;
      t.dtype = DType::f16;
      t.shape = std::move(shape);
      t.bytes.resize(size_t(M.size()) * 2);
      for (Index i = 0; i < M.size(); ++i) {
        uint16_t bits = Imath::half(M.data()[i]).bits();
        t.bytes[2 * i] = uint8_t(bits & 0xff);
        t.bytes[2 * i + 1] = uint8_t(bits >> 8);
      }
      w.add_tensor(std::move(t));
    };
    put("U." + b.name, b.U, {rows, cols});
    put("SxV." + b.name, sxv_scaled, {texels, cols});
    w.add_tensor(Tensor::from_f32("scale." + b.name, {cols}, b.scale.data()));
    w.add_tensor(Tensor::from_f32("S." + b.name, {cols}, b.S.data()));
  }
  return {};
}

}  // namespace btfc::fmf
