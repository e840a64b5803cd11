// Codec and Model: the two interfaces every compression algorithm implements.
//
// A Codec is a stateless factory: parameters (a spec string bound to its ParamSpec table) +
// a Btf -> a Model. A Model is the compressed representation: it decodes (fully, by texel
// region and by light/view subset), evaluates single values at measured or arbitrary
// directions, saves itself as container tensors and reports statistics. Codecs are listed in an
// explicit table (codecs/registry.cpp); adding one is one folder and one line there.
#pragma once
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "core/btf.h"
#include "core/container.h"
#include "core/params.h"
#include "core/progress.h"
#include "core/status.h"

namespace btfc {

class StreamingEncoder;  // codecs/streaming.h
struct EnvironmentSH;    // core/sh.h

// Run-time context: deterministic seed, progress sink, memory limit.
struct Context {
  uint64_t seed = 1;
  Progress* progress = nullptr;  // may be null
  size_t max_bytes = memory_limit();  // core/limits.h: BTFC_MAX_MEMORY or set_memory_limit()
  // The encode's input, when the caller no longer needs its values (`btfc compress`: the BTF it
  // read): an encoder may then use them as scratch memory and leave them changed (fmf's
  // color=dfmf converts it to its colour channels in place, once instead of once per pass). Any
  // other BTF, or null: the input is left as it was.
  Btf* consumable = nullptr;
};

// A texel rectangle plus light/view index subsets (empty = all) to decode.
struct DecodeRequest {
  int x0 = 0, y0 = 0, width = -1, height = -1;  // -1 = to the edge
  std::vector<int> lights, views;
  double lod = 0;  // level of detail for codecs that have one (lpyr); 0 = full detail
};

// One evaluation: a texel and either measured indices (light, view >= 0) or directions.
struct EvalQuery {
  int x = 0, y = 0;
  int light = -1, view = -1;
  Vec3 wl, wv;
};

// The first query outside `d` (texel, or a measured index), as an invalid_argument naming it; ok
// when all are inside. Every eval_batch runs it before evaluating anything.
Status check_eval_queries(const BtfDesc& d, std::span<const EvalQuery> q);

// Named statistics, in insertion order, for `btfc info` / `--json`.
struct ModelStats {
  std::vector<std::pair<std::string, double>> numbers;
  std::vector<std::pair<std::string, std::string>> notes;
  void add(std::string k, double v) { numbers.emplace_back(std::move(k), v); }
  void note(std::string k, std::string v) { notes.emplace_back(std::move(k), std::move(v)); }
};

class Model {
 public:
  virtual ~Model() = default;
  virtual const BtfDesc& desc() const = 0;
  virtual const std::string& spec() const = 0;  // canonical spec string it was made with

  // Decodes a region / direction subset into `out`, which this call (re)creates with the
  // request's shape (subset direction sets, region size); an `out` that already has that
  // shape is reused without reallocation (block-wise decoding of large BTFs).
  virtual Status decode(const DecodeRequest& req, Btf& out) const = 0;
  // Value at a texel and a measured (light, view) index pair; `out` has desc().channels floats.
  virtual void eval(int x, int y, int light, int view, float* out) const = 0;
  // Value at arbitrary directions, interpolated between measured ones (9 lookups).
  virtual Status eval_dir(int x, int y, const Vec3& wl, const Vec3& wv, float* out) const = 0;

  // Many evaluations (out: channels floats per query), the throughput path: the default loops
  // over eval / eval_dir in parallel; codecs with a faster path (OpenCL, blended rows) override
  // it. Every query is checked first (check_eval_queries), so nothing is written on an error.
  virtual Status eval_batch(std::span<const EvalQuery> q, float* out) const;
  // Value at a continuous level of detail (0 = full detail). Codecs without levels of detail
  // answer unsupported for lod != 0.
  virtual Status eval_lod(int x, int y, int light, int view, double lod, float* out) const {
    if (lod != 0) return unsupported(spec() + ": this codec has no levels of detail");
    eval(x, y, light, view, out);
    return {};
  }
  // The arrays a real-time renderer of this codec's paper reads (eigen-textures, weight maps,
  // codebooks, index maps...), named and shaped; exporters lay them out as GPU textures.
  virtual Result<std::vector<Tensor>> gpu_tensors() const { return std::vector<Tensor>{}; }
  // Precomputed radiance transfer for one fixed lighting (codecs whose paper has it: lpca): the
  // model keeps what gpu_tensors() then adds for `env` (world frame, sample lying flat).
  virtual Status attach_environment(const EnvironmentSH& env) {
    return invalid_argument(spec() + ": this codec has no precomputed radiance transfer for an environment");
  }

  // The flat sample (its frame = the world's, z up) under a distant lighting environment given
  // as spherical harmonics, seen from `view_dir` (unit, pointing to the viewer, above the
  // horizon): per texel the quadrature over the measured lights
  //   L(x, v) = sum_l w_l f(x, l, v) E(d_l)
  // with w_l each light direction's Voronoi solid angle (core/sh.h hemisphere_cell_weights; the
  // BTF holds the cosine factor) and views interpolated (Delaunay, 3 measured views). One RGB
  // triple per texel, row-major, the BTF's width x height; one channel is replicated to grey.
  // Works for every codec through eval() (codecs/relight.cpp). lpca overrides it with its
  // precomputed-radiance-transfer path (seed 002), which equals this sum when the environment's
  // order is at most the model's SH order.
  virtual Result<std::vector<float>> relight(const EnvironmentSH& env, const Vec3& view_dir) const;

  // Writes the model's tensors (the container's DESC and CODC are written by the caller).
  virtual Status save(ContainerWriter& w) const = 0;
  // Bytes of the stored model payload (tensors), for the compression ratio.
  virtual uint64_t payload_bytes() const = 0;
  virtual ModelStats stats() const = 0;

  Status decode_all(Btf& out) const { return decode(DecodeRequest{}, out); }
};

class Codec {
 public:
  virtual ~Codec() = default;
  virtual const char* name() const = 0;
  virtual const char* summary() const = 0;  // one line, with the paper
  virtual uint32_t payload_version() const = 0;
  virtual std::span<const ParamSpec> params() const = 0;
  virtual Result<std::unique_ptr<Model>> encode(const Btf& btf, const Params& params, Context& ctx) const = 0;
  // Rebuilds a model from a container; rejects payload versions newer than payload_version().
  virtual Result<std::unique_ptr<Model>> load(const ContainerReader& reader) const = 0;
  // Settings a byte-budget search (codecs/target.h) tries besides the knob: each a spec fragment
  // ("precision=q:bits=6") laid over the spec; keys the user's spec sets are never overridden.
  // For each the knob is searched and the most accurate (PSNR) model that fits wins. Empty: the
  // knob alone. Listed from the most to the least accurate at equal knob (half, then q at falling
  // bit depths): once one fits at budget_knob_limit, the later ones cannot beat it and are skipped.
  // `spec` is the user's spec, resolved (a setting can depend on it: fmf's colour mode).
  virtual std::vector<std::string> budget_variants(const Params& spec) const {
    (void)spec;
    return {};
  }
  // Settings a quality search (--target-psnr / --target-ssim) escalates to, in order, when the
  // knob alone cannot reach the target: spec fragments laid over the spec as budget_variants'
  // (keys the user's spec sets are kept). Empty: the knob alone. For codecs whose quality has
  // more than one limit (mlvq: the knob is one level's threshold of four, the noise cap, the bits).
  virtual std::vector<std::string> quality_variants() const { return {}; }
  // Why --max-bytes cannot search this codec (nullptr: it can): choose_for_target refuses a byte
  // budget with this reason, naming what to use instead, rather than run a search for an hour.
  virtual const char* no_budget_search() const { return nullptr; }
  // The largest quality knob a byte-budget search probes on data of this shape (0: the knob's
  // range); the spec's own knob value is always allowed. Each probe is a whole encode whose cost
  // grows with the knob, and quantized payloads grow slower than linearly with it, so without a
  // limit a search for a large budget walks up to the range's end (lpyr's y to 4096: an hour).
  virtual long long budget_knob_limit(const BtfDesc&) const { return 0; }
  // Out of core (codecs/streaming.h): the encoder that works from column chunks of a BTF it
  // never holds whole, or null when the codec needs the BTF in memory.
  virtual const StreamingEncoder* streaming() const { return nullptr; }
};

// The explicit codec table (codecs/registry.cpp): one entry per codec names the codec and its
// GPU exporter (codecs/gpu_export.h; null when it has none).
namespace gpu {
struct Exporter;
}
struct CodecEntry {
  const Codec* codec;
  const gpu::Exporter* exporter;
};
std::span<const CodecEntry> codec_registry();

// budget_knob_limit of the codecs whose knob counts basis vectors (fmf rank, lpyr y, lpca
// components): one per 64 texels, the rule lpca's default cluster count follows (a basis vector
// estimated from fewer texels fits their noise). 64 on the 64 x 64 textile, 1024 at 256 x 256.
inline long long components_backed_by_texels(const BtfDesc& d) { return (long long)(d.num_texels() / 64); }
std::span<const Codec* const> all_codecs();  // the registry's codecs, in its order
// Appends a codec defined outside the library (tests/toy_codec: the test-only codec) to the
// table: one explicit call, no static self-registration inside the library. Call it before the
// first lookup (not thread-safe); a name already in the table is ignored.
void register_codec(const CodecEntry& entry);
const Codec* find_codec(const std::string& name);

// Parses and binds a spec string ("fmf:rank=32") to its codec's parameter table.
Result<std::pair<const Codec*, Params>> resolve_spec(const std::string& spec);

// Saves a model as a .btfc (DESC + CODC + tensors + STAT), atomically.
Status save_model(const Model& model, const Codec& codec, const std::string& path);
// The bytes save_model would write (container framing and statistics included).
Result<uint64_t> model_file_bytes(const Model& model, const Codec& codec);
// Opens a .btfc holding a model (codec != "raw").
Result<std::unique_ptr<Model>> load_model(const ContainerReader& reader);

// Builds the BtfDesc and index lists a DecodeRequest selects, validating the request.
struct ResolvedRequest {
  BtfDesc desc;                 // output shape
  int x0 = 0, y0 = 0;
  std::vector<int> lights, views;  // source indices, one per output direction
};
Result<ResolvedRequest> resolve_request(const BtfDesc& src, const DecodeRequest& req);
// Makes `out` a BTF of `desc`'s shape: reuses its storage when the value count matches (the
// contents are then stale: the caller overwrites every value), else allocates zeroed storage.
Status prepare_output(const BtfDesc& desc, Btf& out);

}  // namespace btfc
