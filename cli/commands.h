// The btfc subcommands. main.cpp parses the command line (CLI11) into these structs; the
// functions here only call the library and print. Each returns the process exit code:
// 0 ok, 1 usage / invalid argument, 2 I/O or format error, 3 codec or device error.
#pragma once
#include <optional>
#include <string>
#include <vector>

#include "core/btf.h"
#include "core/status.h"

namespace CLI { class App; }
namespace btfc {
class BtfInput;     // formats/reader.h
struct ModelStats;  // codecs/codec.h
}  // namespace btfc

namespace btfc::cli {

struct Global {
  bool json = false;
  bool quiet = false;
  std::string command_line;  // as typed, recorded in benchmark reports
};

int exit_code(const Status& s);
// "THETA,PHI" in degrees -> a unit direction; `what` names the option in the error.
Result<Vec3> parse_theta_phi(const std::string& text, const char* what);
int fail(const Global& g, const Status& s);  // prints "error: ..." (or JSON) and returns exit_code

struct SynthArgs {
  std::string out;
  int width = 32, height = 32;
  std::string lights = "ubo2003", views = "ubo2003";  // ubo2003 | ubo2014 | "THETA,PHI" (one direction, degrees)
  unsigned long long seed = 1;
  float bump = 1.0f, scale = 1.0f, noise = 0.0f;
  std::string format = "exr";  // image-set output: exr | png
};

struct CompressArgs {
  std::string in, out, spec;
  unsigned long long seed = 1;
  // Budget targeting (codecs/target.h): at most one; the codec's quality knob is searched.
  std::optional<double> target_psnr, target_ssim, max_bytes;
  std::string max_memory;  // --max-memory SIZE ("" = default_max_memory())
  std::string work_file;   // --work-file PATH: keep / reuse the out-of-core working file
};

struct DecompressArgs {
  std::string in, out;
  std::string region;               // "x,y,w,h"
  std::string lights, views;        // "0,3,5"
  std::string format = "exr";
  double lod = 0;                   // level of detail (lpyr); 0 = full detail
  std::string max_memory;
};

struct EvalArgs {
  std::string in;
  std::string texel;                // "x,y"
  std::optional<int> light, view;   // measured indices
  std::string wl, wv;               // "theta,phi" in degrees
  double lod = 0;
};

struct RelightArgs {
  std::string in, env, view, out;  // view: "theta,phi" degrees
  int order = 5;
};

struct ConvertArgs {
  std::string in, out;
  std::string precision = "half";  // Bonn output scalars
};

struct CompareArgs {
  std::string a, b;
  bool ssim = true;
};

struct BenchArgs {
  std::string in;
  std::vector<std::string> specs;  // each may be a sweep: fmf:rank=4,8,16
  std::string label;
  bool header = true;
  unsigned long long seed = 1;
  std::string csv, json_out;       // files (csv: appended to with --append)
  bool append = false;
  std::string renders_dir;         // side-by-side PNGs per run and scene
  bool pareto = false;
  bool no_renders = false;
  size_t throughput_queries = size_t(1) << 17;
  std::string max_memory;          // --max-memory: larger inputs stream (fmf, cli/stream_commands.cpp)
};

struct RenderArgs {
  std::string in, out;
  std::string shape = "flat";      // flat | sphere
  std::string view = "0,0";        // THETA,PHI degrees
  std::string light = "30,0";      // THETA,PHI degrees (directional / point)
  double distance = 0;             // > 0: point light at this distance
  std::string env;                 // lat-long EXR: environment lighting
  double intensity = 1;
  int size = 256, tiles = 1;
  double exposure = 0;             // EV: values x 2^exposure
  std::string tonemap = "none";    // none | reinhard
};

// Applies --device (auto | cpu | cl) to the process (core/cl_runtime.h); auto, the default, leaves
// the process's choice (auto, or cpu under BTFC_FORCE_CPU=1).
void set_device(const std::string& choice);

int cmd_devices(const Global& g);
int cmd_codecs(const Global& g, bool names_only);
int cmd_synth(const Global& g, const SynthArgs& a);
int cmd_info(const Global& g, const std::string& path, bool verify);
int cmd_compress(const Global& g, const CompressArgs& a);
int cmd_decompress(const Global& g, const DecompressArgs& a);
int cmd_eval(const Global& g, const EvalArgs& a);
int cmd_compare(const Global& g, const CompareArgs& a);
int cmd_relight(const Global& g, const RelightArgs& a);
int cmd_convert(const Global& g, const ConvertArgs& a);
int cmd_bench(const Global& g, const BenchArgs& a);
int cmd_render(const Global& g, const RenderArgs& a);

// A parameter the codec could not honour as asked (its stats notes "clamped..." / "..._clamped":
// a rank above the data's size, levels beyond the texture): one "note:" line each on stderr. The
// model's spec holds the value used.
void note_clamped(const Global& g, const std::string& input, const ModelStats& stats);

// Bounded memory (cli/stream_commands.cpp): each returns true when it handled the command
// (the BTF does not fit in --max-memory, or the output is a streamed Bonn BDI), with `code` set.
bool compress_streamed(const Global& g, const CompressArgs& a, BtfInput& input, int& code);
bool decompress_streamed(const Global& g, const DecompressArgs& a, int& code);
bool bench_streamed(const Global& g, const BenchArgs& a, BtfInput& input, int& code);

// `bsvtf` and `tilecache` (cli/bsvtf_commands.cpp): registers both on `app`; they set `code`.
void add_bsvtf_commands(CLI::App& app, const Global& g, int& code);
// `export` (cli/export_commands.cpp) likewise: its arguments live in that file.
void add_export_commands(CLI::App& app, const Global& g, int& code);
// `view` (cli/view_command.cpp): serves the web viewer (viewer/) for export directories.
void add_view_command(CLI::App& app, const Global& g, int& code);

}  // namespace btfc::cli
