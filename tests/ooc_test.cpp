// Tests of the out-of-core path: BDI working files (writer, chunk reader, completion marker),
// the streaming randomized SVD against the in-core one, processes simulated by threads, and
// failures that must reach every process.
#include <gtest/gtest.h>
#include <unistd.h>

#include <Eigen/Dense>
#include <Imath/half.h>
#include <barrier>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <mutex>
#include <random>
#include <thread>

#include "codecs/codec.h"
#include "codecs/fmf/ooc_fmf.h"
#include "core/svd.h"
#include "core/synth.h"
#include "formats/bonn/bdi_work.h"
#include "formats/bonn/bonn_btf.h"
#include "tests/ooc_test_util.h"
#include "tests/svd_test_util.h"

using namespace btfc;
using namespace btfc::ooc_test;

TEST(BdiWork, RoundTripThroughWriterChunksAndTheBonnReader) {
  const Btf b = synth(9, 7);
  const std::string path = tmp_path("rt.btf");
  ASSERT_TRUE(write_bdi(b, path, 2).ok());
  auto f = BdiChunks::open(path);
  ASSERT_TRUE(f.ok()) << f.status().message();
  EXPECT_EQ(f->num_chunks(), 4u);  // 7 rows / 2 per chunk
  EXPECT_EQ(f->chunk_count(3), 9u);
  const size_t m = b.desc().abrdf_size();
  double max_rel = 0;
  for (uint64_t c = 0; c < f->num_chunks(); ++c) {
    std::vector<uint16_t> raw(f->chunk_bytes(c) / 2);
    std::vector<float> v(raw.size());
    ASSERT_TRUE(f->read_raw(c, raw.data()).ok());
    ASSERT_TRUE(f->decode(c, raw.data(), v.data()).ok());
    for (size_t i = 0; i < v.size(); ++i) {
      const float want = b.data()[f->chunk_first(c) * m + i];
      EXPECT_EQ(v[i], float(Imath::half(want))) << "chunk " << c << " value " << i;
      if (want > 1e-3f) max_rel = std::max(max_rel, std::fabs(double(v[i]) - want) / want);
    }
  }
  EXPECT_LT(max_rel, 1.0 / 1024);
  // The existing Bonn BDI reader reads the same values: the working file is a valid .btf.
  auto model = open_bonn_model(path);
  ASSERT_TRUE(model.ok()) << model.status().message();
  float rgb[3];
  model.value()->eval(4, 5, 17, 1, rgb);
  EXPECT_EQ(rgb[1], float(Imath::half(b.at(4, 5, 17, 1, 1))));
  std::remove(path.c_str());
}

// Chunks start at an even offset whatever the XML's length (the writer pads it), so their half
// floats are decoded straight from the mapping; at an odd offset every chunk took a copy (a
// pass ~10 x slower). Read back equal either way.
TEST(BdiWork, ChunksStartAtAnEvenOffset) {
  const Btf b = synth(8, 4);
  for (const std::string xml : {"<a/>", "<ab/>"}) {
    const std::string path = tmp_path("even.btf");
    {
      auto w = BdiWriter::create(path, b.desc(), 1, 1.0f, xml);
      ASSERT_TRUE(w.ok());
      ASSERT_TRUE(w.value()->write_texels(0, b.desc().num_texels(), b.data()).ok());
      ASSERT_TRUE(w.value()->finish().ok());
    }
    std::ifstream f(path, std::ios::binary | std::ios::ate);
    const uint64_t size = uint64_t(f.tellg());
    auto c = BdiChunks::open(path);
    ASSERT_TRUE(c.ok()) << c.status().message();
    const uint64_t data = size - c->num_chunks() * 4 - b.desc().num_texels() * b.desc().abrdf_size() * 2;
    EXPECT_EQ(data % 2, 0u) << xml << ": chunks at " << data;
    std::vector<float> chunk(c->chunk_count(0) * b.desc().abrdf_size());
    ASSERT_TRUE(c->read_decoded(0, chunk.data()).ok());
    for (size_t i = 0; i < chunk.size(); ++i) ASSERT_EQ(chunk[i], float(Imath::half(b.data()[i]))) << xml << " " << i;
    std::remove(path.c_str());
  }
}

TEST(BdiWork, InterruptedFileIsDetectedAndNotTrusted) {
  const Btf b = synth(8, 4);
  const std::string path = tmp_path("part.btf");
  {
    auto w = BdiWriter::create(path, b.desc(), 1, 1.0f, "");
    ASSERT_TRUE(w.ok());
    ASSERT_TRUE(w.value()->write_texels(0, 16, b.data()).ok());
    // Mid-run (as after a crash here): the file exists, but is not a BTF.
    auto f = BdiChunks::open(path);
    ASSERT_FALSE(f.ok());
    EXPECT_EQ(f.status().code(), StatusCode::corrupt_data);
    EXPECT_NE(f.status().message().find("incomplete working file"), std::string::npos) << f.status().message();
    auto m = open_bonn_model(path);
    ASSERT_FALSE(m.ok());
    EXPECT_NE(m.status().message().find("incomplete"), std::string::npos) << m.status().message();
  }
  // A writer that never finished removes its file.
  EXPECT_FALSE(std::ifstream(path).good());
}

TEST(BdiWork, ValuesBeyondHalfAskForAScaleAndScaledFilesReadBack) {
  const Btf b = synth(6, 4, 1e6f);  // HDR: far beyond 65504
  const std::string path = tmp_path("hdr.btf");
  {
    auto w = BdiWriter::create(path, b.desc(), 2, 1.0f, "");
    ASSERT_TRUE(w.ok());
    EXPECT_FALSE(w.value()->write_texels(0, b.desc().num_texels(), b.data()).ok());
    EXPECT_GT(w.value()->overflow(), 65504.0f);
  }
  ASSERT_TRUE(write_bdi(b, path, 2, 64.0f).ok());
  auto f = BdiChunks::open(path);
  ASSERT_TRUE(f.ok());
  EXPECT_EQ(f->scale(), 64.0f);
  std::vector<uint16_t> raw(f->chunk_bytes(0) / 2);
  std::vector<float> v(raw.size());
  ASSERT_TRUE(f->read_raw(0, raw.data()).ok());
  ASSERT_TRUE(f->decode(0, raw.data(), v.data()).ok());
  for (size_t i = 0; i < v.size(); i += 97)
    EXPECT_NEAR(v[i], b.data()[i], std::fabs(b.data()[i]) * 1e-3 + 64 * 6e-8) << i;
  // The mapped path (no raw buffer) decodes the same values, for every chunk.
  for (uint64_t c = 0; c < f->num_chunks(); ++c) {
    std::vector<float> mapped(f->chunk_count(c) * b.desc().abrdf_size()), copied(mapped.size());
    ASSERT_TRUE(f->read_decoded(c, mapped.data()).ok());
    ASSERT_TRUE(f->read_raw(c, raw.data()).ok());
    ASSERT_TRUE(f->decode(c, raw.data(), copied.data()).ok());
    EXPECT_EQ(mapped, copied) << "chunk " << c;
  }
  std::remove(path.c_str());
}

TEST(StreamingSvd, MatchesTheInCoreRandomizedSvd) {
  const Btf b = synth(24, 20);  // 486 x 480
  const size_t m = b.desc().abrdf_size(), n = b.desc().num_texels();
  SvdOptions opt;
  opt.max_rank = 12, opt.oversample = 8, opt.power_iters = 2, opt.method = SvdMethod::randomized;
  auto in_core = truncated_svd(b.data(), m, n, opt);
  ASSERT_TRUE(in_core.ok());
  MemorySource src(b, 72);  // 7 chunks, the last one short
  Collective one;
  StreamStats st;
  auto streamed = fmf::streaming_svd(src, owned_chunks(src, 0, 1), opt, one, &st);
  ASSERT_TRUE(streamed.ok()) << streamed.status().message();
  EXPECT_EQ(st.passes, opt.power_iters + 2);
  EXPECT_EQ(st.bytes_read, uint64_t(opt.power_iters + 2) * m * n * 4);
  ASSERT_EQ(streamed->U.cols(), 12);
  ASSERT_EQ(size_t(streamed->SxV.rows()), n);
  const double e_in = actual_error(b, in_core.value()), e_st = actual_error(b, streamed.value());
  EXPECT_GT(e_st, 0.001);  // rank 12 of this data is not exact: the comparison means something
  EXPECT_LT(std::fabs(e_st - e_in) / e_in, 0.01) << "in-core " << e_in << ", streamed " << e_st;
  EXPECT_NEAR(streamed->rel_error_estimate(), e_st, 0.01 * e_st);
  // Orthonormal U.
  EXPECT_LT((streamed->U.transpose().cast<double>() * streamed->U.cast<double>() - Eigen::MatrixXd::Identity(12, 12)).norm(), 1e-4);
}

// The streamed SVD is block Krylov on the rows side with the in-core error-driven stop: with a
// large q it stops once a block gains less than 0.2 % of the error, reading B fewer than q + 2
// times, at the exact SVD's error within 1 %.
TEST(StreamingSvd, BlockKrylovStopsEarlyAtTheOptimum) {
  const Btf b = synth(24, 20);  // 486 x 480
  const size_t m = b.desc().abrdf_size(), n = b.desc().num_texels();
  SvdOptions opt;
  opt.max_rank = 12, opt.oversample = 8, opt.power_iters = 8, opt.method = SvdMethod::exact;
  auto exact = truncated_svd(b.data(), m, n, opt);
  ASSERT_TRUE(exact.ok());
  MemorySource src(b, 72);
  Collective one;
  StreamStats st;
  auto streamed = fmf::streaming_svd(src, owned_chunks(src, 0, 1), opt, one, &st);
  ASSERT_TRUE(streamed.ok()) << streamed.status().message();
  EXPECT_GE(streamed->iterations, 2);
  EXPECT_LT(streamed->iterations, opt.power_iters + 1) << "the error-driven stop";
  EXPECT_EQ(st.passes, streamed->iterations + 1);
  EXPECT_EQ(st.bytes_read, uint64_t(st.passes) * m * n * 4);
  const double e_ex = actual_error(b, exact.value()), e_st = actual_error(b, streamed.value());
  EXPECT_GE(e_st, e_ex * (1 - 1e-6));
  EXPECT_LE(e_st, e_ex * 1.01) << "exact " << e_ex << ", streamed " << e_st;
  EXPECT_NEAR(streamed->rel_error_estimate(), e_st, 0.01 * e_st);
}

// Under a tight memory limit the basis holds only kept_blocks blocks and restarts from its Ritz
// vectors when full (1 is the power iteration): every cap still reaches the exact SVD's error
// within 1 % on this data, in at most q + 2 reads, and the full basis is never worse than one
// kept block. (Dropping the oldest block instead ended at an error of 0.99 with 3 kept.)
TEST(StreamingSvd, AWindowOfKrylovBlocksStillConverges) {
  const Btf b = synth(24, 20);  // 486 x 480
  const size_t m = b.desc().abrdf_size(), n = b.desc().num_texels();
  SvdOptions opt;
  opt.max_rank = 12, opt.oversample = 4, opt.power_iters = 3, opt.method = SvdMethod::exact;
  auto exact = truncated_svd(b.data(), m, n, opt);
  ASSERT_TRUE(exact.ok());
  const double e_ex = actual_error(b, exact.value());
  MemorySource src(b, 72);
  Collective one;
  double e_first = 0;
  for (int kept : {1, 2, 3, 0}) {
    StreamStats st;
    auto r = fmf::streaming_svd(src, owned_chunks(src, 0, 1), opt, one, &st, kept);
    ASSERT_TRUE(r.ok()) << r.status().message();
    EXPECT_LE(st.passes, opt.power_iters + 2) << "kept " << kept;
    const double e = actual_error(b, r.value());
    EXPECT_GE(e, e_ex * (1 - 1e-6)) << "kept " << kept;
    EXPECT_LE(e, e_ex * 1.01) << "kept " << kept << ": exact " << e_ex << ", streamed " << e;
    EXPECT_NEAR(r->rel_error_estimate(), e, 0.01 * e) << "kept " << kept;
    if (kept == 1) e_first = e;
    if (kept == 0) {
      EXPECT_LE(e, e_first * (1 + 1e-4));
    }
  }
}

// The streamed Krylov SVD (its first pass through the sparse sign sketch: 1200 rows >= 4 x 256
// buckets) at the extremes, against the exact SVD: zeros, a constant, rank 2, HDR rows 1e-6..1e6;
// with the whole basis and with one kept block (the power iteration).
TEST(StreamingSvd, HoldsAtTheExtremes) {
  const size_t m = 1200, n = 300;
  for (const auto& c : test::extreme_matrices(m, n, 21)) {
    SvdOptions o;
    o.max_rank = 8, o.oversample = 8, o.power_iters = 3, o.method = SvdMethod::exact;
    auto exact = truncated_svd(c.b.data(), m, n, o);
    ASSERT_TRUE(exact.ok()) << c.name;
    const MatrixChunks src(c.b.data(), m, n, 64);  // mapped chunks of 64 texels
    Collective one;
    for (int kept : {0, 1}) {
      auto r = fmf::streaming_svd(src, owned_chunks(src, 0, 1), o, one, nullptr, kept);
      ASSERT_TRUE(r.ok()) << c.name << ": " << r.status().message();
      test::expect_like_exact(c, m, n, *r, *exact, std::string(c.name) + " kept " + std::to_string(kept));
    }
  }
}

TEST(StreamingSvd, ThreeProcessesGiveTheOneProcessResult) {
  const Btf b = synth(16, 15);
  MemorySource src(b, 32);  // 8 chunks over 3 processes
  SvdOptions opt;
  opt.max_rank = 8, opt.oversample = 6, opt.power_iters = 2;
  Collective one;
  auto ref = fmf::streaming_svd(src, owned_chunks(src, 0, 1), opt, one);
  ASSERT_TRUE(ref.ok());
  std::vector<Result<SvdResult>> res(3, Result<SvdResult>(Status{}));
  run_group(3, [&](Collective& me, int r) { res[size_t(r)] = fmf::streaming_svd(src, owned_chunks(src, r, 3), opt, me); });
  for (int r = 0; r < 3; ++r) ASSERT_TRUE(res[size_t(r)].ok()) << res[size_t(r)].status().message();
  const auto& got = res[0].value();
  ASSERT_EQ(got.SxV.rows(), ref->SxV.rows());
  EXPECT_TRUE(res[1]->SxV.size() == 0 && res[2]->SxV.size() == 0);
  // The reconstruction U SxV^T (invariant to signs of components) agrees to float rounding.
  Eigen::MatrixXd A = ref->U.cast<double>() * ref->SxV.cast<double>().transpose();
  Eigen::MatrixXd B = got.U.cast<double>() * got.SxV.cast<double>().transpose();
  EXPECT_LT((A - B).norm() / A.norm(), 1e-4);
  EXPECT_GT(A.norm(), 0);
}

// A first pass with the sparse sketch (n >= 4 s texels): the chunks' B S summed into one buffer
// and multiplied by G once (SvdOptions::sketch_sums, the default), or each chunk's B S G on its
// own (the plan's choice under a tight limit), over one process or three: the same basis to
// float rounding (the buffer holds the bits of the whole matrix's B S: svd_test.cpp).
TEST(StreamingSvd, SketchSumsOverTheChunksGiveTheSameResult) {
  const Btf b = synth(40, 32);  // 1280 texels: n >= 4 s at s = 256
  const size_t m = b.desc().abrdf_size(), n = b.desc().num_texels();
  SvdOptions opt;
  opt.max_rank = 10, opt.oversample = 6, opt.power_iters = 1;
  ASSERT_GT(column_sketch_sums_bytes(m, n, 16), 0u);
  MemorySource src(b, 100);  // 13 chunks, the last one short
  Collective one;
  auto sums = fmf::streaming_svd(src, owned_chunks(src, 0, 1), opt, one);
  opt.sketch_sums = false;
  auto apart = fmf::streaming_svd(src, owned_chunks(src, 0, 1), opt, one);
  opt.sketch_sums = true;
  std::vector<Result<SvdResult>> res(3, Result<SvdResult>(Status{}));
  run_group(3, [&](Collective& me, int r) { res[size_t(r)] = fmf::streaming_svd(src, owned_chunks(src, r, 3), opt, me); });
  ASSERT_TRUE(sums.ok() && apart.ok()) << sums.status().message() << apart.status().message();
  for (int r = 0; r < 3; ++r) ASSERT_TRUE(res[size_t(r)].ok()) << res[size_t(r)].status().message();
  const Eigen::MatrixXd A = sums->U.cast<double>() * sums->SxV.cast<double>().transpose();
  for (const SvdResult* other : {&apart.value(), &res[0].value()}) {
    const Eigen::MatrixXd B = other->U.cast<double>() * other->SxV.cast<double>().transpose();
    EXPECT_LT((A - B).norm() / A.norm(), 1e-4);
    EXPECT_LT((sums->S - other->S).cwiseAbs().maxCoeff(), 1e-5 * sums->S(0));
  }
  EXPECT_GT(actual_error(b, sums.value()), 1e-3);  // rank 10 is not exact here: the comparison means something
}

TEST(StreamingSvd, AFailingProcessStopsEveryProcessWithItsMessage) {
  const Btf b = synth(16, 15);
  MemorySource src(b, 32);
  src.fail_chunk = 7;  // owned by process 2 of 3
  SvdOptions opt;
  opt.max_rank = 8, opt.oversample = 6, opt.power_iters = 1;
  std::vector<Status> st(3);
  run_group(3, [&](Collective& me, int r) { st[size_t(r)] = fmf::streaming_svd(src, owned_chunks(src, r, 3), opt, me).status(); });
  for (int r = 0; r < 3; ++r) {
    EXPECT_EQ(st[size_t(r)].code(), StatusCode::io_error) << r;
    EXPECT_NE(st[size_t(r)].message().find("rank 2: cannot read chunk 7"), std::string::npos) << st[size_t(r)].message();
  }
}

TEST(StreamingFmf, WorkingFileEncodeMatchesInCoreFmf) {
  const Btf b = synth(20, 18);
  const std::string path = tmp_path("enc.btf");
  ASSERT_TRUE(write_bdi(b, path, 3).ok());
  auto file = BdiChunks::open(path);
  ASSERT_TRUE(file.ok());
  auto spec = resolve_spec("fmf:rank=10:oversample=8:power_iters=3:svd=randomized");
  ASSERT_TRUE(spec.ok());
  Context ctx;
  auto in_core = spec->first->encode(b, spec->second, ctx);
  ASSERT_TRUE(in_core.ok());
  Collective one;
  auto st = encode_fmf_streamed(BdiChunkSource(file.value()), b.desc(), spec->second, ctx, one);
  ASSERT_TRUE(st.ok()) << st.status().message();
  ASSERT_TRUE(st->model);
  EXPECT_EQ(st->model->spec(), in_core.value()->spec());
  const double e_in = model_error(b, *in_core.value()), e_st = model_error(b, *st->model);
  EXPECT_GT(e_in, 0.002);
  EXPECT_LT(std::fabs(e_st - e_in) / e_in, 0.01) << "in-core " << e_in << ", streamed " << e_st;
  std::remove(path.c_str());
}

TEST(StreamingFmf, NonFiniteValueInAChunkIsAnErrorNamingIt) {
  Btf b = synth(8, 6);
  const std::string path = tmp_path("nan.btf");
  ASSERT_TRUE(write_bdi(b, path, 2).ok());
  auto f0 = BdiChunks::open(path);
  ASSERT_TRUE(f0.ok());
  // A half NaN (0x7e00) in the last chunk, written over the file.
  {
    std::fstream io(path, std::ios::in | std::ios::out | std::ios::binary);
    io.seekp(std::streamoff(f0->file_size() - 10));
    const uint16_t nan = 0x7e00;
    io.write(reinterpret_cast<const char*>(&nan), 2);
  }
  auto file = BdiChunks::open(path);
  ASSERT_TRUE(file.ok());
  auto spec = resolve_spec("fmf:rank=4:oversample=4:power_iters=1");
  Context ctx;
  Collective one;
  auto st = encode_fmf_streamed(BdiChunkSource(file.value()), b.desc(), spec->second, ctx, one);
  ASSERT_FALSE(st.ok());
  EXPECT_EQ(st.status().code(), StatusCode::corrupt_data);
  EXPECT_NE(st.status().message().find("BDI chunk 2 holds a non-finite value at texel (7, 5)"), std::string::npos) << st.status().message();
  std::remove(path.c_str());
}

TEST(BdiWork, ImageGroupsWriteTheSameFileAsTexelBands) {
  const Btf b = synth(7, 5);
  const BtfDesc& d = b.desc();
  const std::string a = tmp_path("bands.btf"), c = tmp_path("images.btf");
  ASSERT_TRUE(write_bdi(b, a, 2).ok());
  {
    auto w = BdiWriter::create(c, d, 2, 1.0f, "<btfc_work scale=\"1.000000\"/>");
    ASSERT_TRUE(w.ok());
    // Groups of 11 images (the last one short), image-major as read_images delivers them.
    const size_t texels = d.num_texels(), nc = size_t(d.channels);
    for (size_t i0 = 0; i0 < d.num_images(); i0 += 11) {
      const size_t k = std::min<size_t>(11, d.num_images() - i0);
      std::vector<float> img(k * texels * nc);
      for (size_t j = 0; j < k; ++j)
        for (size_t t = 0; t < texels; ++t)
          for (size_t ch = 0; ch < nc; ++ch) img[(j * texels + t) * nc + ch] = b.abrdf(t)[(i0 + j) * nc + ch];
      ASSERT_TRUE(w.value()->write_images(i0, k, img.data()).ok());
    }
    ASSERT_TRUE(w.value()->finish().ok());
  }
  std::ifstream fa(a, std::ios::binary), fc(c, std::ios::binary);
  const std::string sa((std::istreambuf_iterator<char>(fa)), {}), sc((std::istreambuf_iterator<char>(fc)), {});
  EXPECT_GT(sa.size(), d.num_values() * 2);
  EXPECT_TRUE(sa == sc) << "the two writers' files differ";
  std::remove(a.c_str());
  std::remove(c.c_str());
}
