// btfc-mpi: compression of any codec that streams (Codec::streaming(): fmf) spread over MPI ranks
// (mpirun -n N btfc-mpi compress ...). The encode is formats/out_of_core.h's compress_out_of_core.
//
//   btfc-mpi compress INPUT -c SPEC -o OUT [--max-memory SIZE] [--work-file PATH] [--seed N] [--json] [-q]
//
// A raw .btfc input (without --work-file) is read in place: every rank maps only its own texel
// chunks and the tensor CRC is joined over the ranks after the first pass, so no rank reads the
// whole input. Otherwise rank 0 prepares the working file (formats/btf_stream.h; an
// uncompressed Bonn BDI input is used as it is), every rank opens it and reads only its own
// texel chunks. Each pass of the
// streamed SVD is local GEMMs plus one MPI_Allreduce (codecs/fmf/ooc_svd.h, mpi_collective.h),
// and rank 0 writes the model. The model equals `btfc compress` of the same input up to float
// rounding (tests/mpi_test.sh). Every failure is agreed on by all ranks (MpiCollective::agree),
// so all exit with the same message and code, none hangs. --max-memory is per rank. Paths
// must name the same file on every rank (one machine, or a shared file system).
// Exit codes as btfc: 0 ok, 1 usage, 2 I/O or format, 3 codec.
#include <mpi.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <memory>
#include <optional>
#include <nlohmann/json.hpp>
#include <string>

#include "codecs/codec.h"
#include "core/blas_env.h"
#include "core/memory.h"
#include "formats/btf_io.h"
#include "formats/btf_stream.h"
#include "formats/out_of_core.h"
#include "mpi/mpi_collective.h"

using namespace btfc;
using nlohmann::json;

namespace {

struct Args {
  std::string in, out, spec, max_memory, work_file;
  unsigned long long seed = 1;
  bool json = false, quiet = false;
};

const char* k_usage =
    "usage: mpirun -n N btfc-mpi compress INPUT -c SPEC -o OUT [--max-memory SIZE] [--work-file PATH] [--seed N] [--json] [-q]\n";

Status parse_args(int argc, char** argv, Args& a) {
  if (argc < 2 || std::string(argv[1]) != "compress") return invalid_argument("expected the subcommand 'compress'");
  for (int i = 2; i < argc; ++i) {
    const std::string s = argv[i];
    auto value = [&](std::string& dst) -> Status {
      if (i + 1 >= argc) return invalid_argument(s + " needs a value");
      dst = argv[++i];
      return {};
    };
    std::string seed;
    if (s == "-c" || s == "--codec") BTFC_RETURN_IF_ERROR(value(a.spec));
    else if (s == "-o" || s == "--output") BTFC_RETURN_IF_ERROR(value(a.out));
    else if (s == "--max-memory") BTFC_RETURN_IF_ERROR(value(a.max_memory));
    else if (s == "--work-file") BTFC_RETURN_IF_ERROR(value(a.work_file));
    else if (s == "--seed") {
      BTFC_RETURN_IF_ERROR(value(seed));
      char* end = nullptr;
      a.seed = std::strtoull(seed.c_str(), &end, 10);
      if (seed.empty() || *end) return invalid_argument("--seed: '" + seed + "' is not an integer");
    } else if (s == "--json") a.json = true;
    else if (s == "-q" || s == "--quiet") a.quiet = true;
    else if (!s.empty() && s[0] != '-' && a.in.empty()) a.in = s;
    else return invalid_argument("unknown argument '" + s + "'");
  }
  if (a.in.empty() || a.out.empty() || a.spec.empty()) return invalid_argument("INPUT, -c SPEC and -o OUT are required");
  return {};
}

int exit_code(const Status& s) {
  switch (s.code()) {
    case StatusCode::ok: return 0;
    case StatusCode::invalid_argument: return 1;
    case StatusCode::codec_error:
    case StatusCode::device_error: return 3;
    default: return 2;
  }
}

double since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

int run(int argc, char** argv, MpiCollective& coll) {
  const bool root = coll.rank() == 0;
  const auto t_start = std::chrono::steady_clock::now();
  auto finish = [&](const Status& s) {
    if (!s.ok() && root) {
      if (std::getenv("BTFC_MPI_JSON_ERRORS")) std::cout << json{{"error", s.message()}}.dump() << "\n";
      std::cerr << "error: " << s.message() << "\n";
    }
    return exit_code(s);
  };
  Args a;
  Status s = parse_args(argc, argv, a);
  if (!s.ok()) {
    if (root) std::cerr << k_usage;
    return finish(s);
  }
  auto limit = a.max_memory.empty() ? Result<size_t>(default_max_memory()) : parse_size(a.max_memory);
  if (!limit.ok()) return finish(limit.status());
  // The whole streamed encode (in place or through rank 0's working file, agreed failures) is
  // the library's (formats/out_of_core.h), the same call `btfc compress --max-memory` makes.
  Progress progress(a.quiet || a.json || !root);
  OutOfCoreJob job;
  std::string note;  // the output's writer may adapt the spec (a Bonn DFMF holds only colour model 11's offset)
  job.input = a.in, job.spec = spec_for_output(a.spec, a.out, &note), job.max_bytes = *limit, job.seed = a.seed, job.work_file = a.work_file;
  if (!note.empty() && root && !a.quiet && !a.json) std::cerr << "note: " << a.out << ": " << note << "\n";
  std::error_code ec;
  job.temp_dir = std::filesystem::absolute(a.out, ec).parent_path().string();
  job.progress = &progress;
  job.notes = root && !a.quiet && !a.json;
  auto enc = compress_out_of_core(job, coll);
  if (!enc.ok()) return finish(enc.status());
  const double factor_s = enc->factorize_seconds;
  const bool in_place = enc->in_place;
  const WorkFile& wf = enc->work;
  if (root) s = write_model(*enc->model, a.out);
  s = coll.agree(s);
  if (!s.ok()) {
    MPI_Barrier(MPI_COMM_WORLD);
    return finish(s);
  }

  // Per-rank measurements, gathered for the report.
  double mine[4] = {double(enc->stats.bytes_read), 0, enc->stats.reduce_seconds, double(peak_rss_bytes())};
  for (double p : enc->stats.pass_seconds) mine[1] += p;
  std::vector<double> all(size_t(4 * coll.size()));
  MPI_Gather(mine, 4, MPI_DOUBLE, all.data(), 4, MPI_DOUBLE, 0, MPI_COMM_WORLD);
  if (root) {
    json ranks = json::array();
    for (int r = 0; r < coll.size(); ++r)
      ranks.push_back({{"rank", r}, {"bytes_read", all[4 * r]}, {"pass_seconds", all[4 * r + 1]}, {"reduce_seconds", all[4 * r + 2]},
                       {"peak_rss_bytes", all[4 * r + 3]}});
    json j{{"input", a.in}, {"output", a.out}, {"spec", enc->model->spec()}, {"ranks", coll.size()}, {"work_file", wf.path},
           {"in_place", in_place}, {"work_file_built", wf.built}, {"work_file_seconds", wf.seconds}, {"passes", enc->stats.passes},
           {"pass_seconds_rank0", enc->stats.pass_seconds}, {"allreduce_bytes_per_rank", enc->stats.reduce_bytes},
           {"factorize_seconds", factor_s}, {"total_seconds", since(t_start)}, {"per_rank", ranks}};
    if (a.json) std::cout << j.dump(2) << "\n";
    else if (!a.quiet)
      std::cout << "compressed " << a.in << " on " << coll.size() << " ranks with " << enc->model->spec() << " -> " << a.out << "\n  "
                << enc->stats.passes << " passes, factorization " << factor_s << " s, rank 0 read "
                << format_bytes(enc->stats.bytes_read) << ", allreduce " << enc->stats.reduce_seconds << " s\n";
  }
  MPI_Barrier(MPI_COMM_WORLD);  // every rank is done reading before rank 0 removes a temporary working file (~enc)
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  reexec_for_openblas(argc, argv);  // before MPI_Init: execv replaces the process image
  MPI_Init(&argc, &argv);
  int code = 0;
  {
    MpiCollective coll(MPI_COMM_WORLD);
    code = run(argc, argv, coll);
  }
  MPI_Finalize();
  return code;
}
