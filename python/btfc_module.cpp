// The Python module `btfc`: btfc's library on numpy arrays (docs/API.md "Python").
//
// The data model is the CLI's: the same readers (btfc.open reads every input `btfc` reads), the
// same spec strings, the same codecs, metrics and bench rows, so a notebook's numbers equal the
// command line's on the same input (tests/python/test_btfc.py checks that against the binary).
//
// Arrays: a Btf's values are one numpy view of btfc's own buffer, shape
// (height, width, views, lights, channels), float32, C order: exactly btfc's pinned texel-major
// layout (core/btf.h), so no copy is made; the view keeps the buffer alive. An array given to
// btfc.Btf(...) is copied once (btfc's storage is 2 MiB aligned for huge pages). Evaluations are
// written straight into the returned array.
//
// Long calls (open, compress, decode, bench, compare, save, export) release the GIL; a
// `progress=` callable receives (stage, done, total) at most every 100 ms, from the thread that
// advanced the work, with the GIL held. An exception it raises is re-raised when the call returns.
// Errors are btfc.Error (a RuntimeError) carrying btfc's message and its `code`
// ("invalid_argument", "io_error", "corrupt_data", ...), as the CLI prints them.
#include <pybind11/functional.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <cmath>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "btfc_python.h"
#include "codecs/gpu_export.h"
#include "codecs/measure.h"
#include "codecs/target.h"
#include "core/cl_runtime.h"
#include "core/limits.h"
#include "core/synth.h"
#include "core/sysinfo.h"
#include "formats/bsvtf/bsvtf_export.h"
#include "formats/btf_io.h"
#include "formats/gpu/export.h"
#include "formats/reader.h"

namespace py = pybind11;
using namespace btfc;
using namespace btfc::python;

namespace {

py::dict metrics_dict(const Metrics& m) {
  py::dict d;
  d["rmse"] = m.rmse;
  d["rel_l2"] = m.rel_l2;
  d["psnr"] = m.psnr;
  d["psnr_peak"] = m.peak;
  d["mean_ssim"] = m.mean_ssim;
  d["ssim_range"] = m.ssim_range == Metrics::SsimRange::ldr_one ? "ldr_one" : "per_image_max";
  d["max_abs"] = m.max_abs;
  return d;
}

py::list codecs_list() {
  py::list out;
  for (const CodecEntry& e : codec_registry()) {
    py::list params;
    for (const ParamSpec& p : e.codec->params()) {
      py::dict d;
      d["name"] = p.name;
      d["type"] = p.type == ParamSpec::Type::integer ? "integer" : p.type == ParamSpec::Type::real ? "real" : "choice";
      d["default"] = p.default_value;
      if (p.type == ParamSpec::Type::choice) d["choices"] = p.choices;
      else {
        d["min"] = p.min;
        d["max"] = p.max;
      }
      d["help"] = p.help;
      d["quality_knob"] = p.quality_knob;
      params.append(d);
    }
    py::dict c;
    c["name"] = e.codec->name();
    c["summary"] = e.codec->summary();
    c["payload_version"] = e.codec->payload_version();
    c["exporter"] = e.exporter != nullptr;
    c["streaming"] = e.codec->streaming() != nullptr;
    c["params"] = params;
    out.append(c);
  }
  return out;
}

std::vector<std::string> spec_list(const py::object& specs) {
  std::vector<std::string> given;
  if (py::isinstance<py::str>(specs)) given.push_back(specs.cast<std::string>());
  else
    for (const py::handle& h : specs) given.push_back(h.cast<std::string>());
  std::vector<std::string> out;
  for (const std::string& s : given) {
    for (const std::string& e : unwrap(expand_sweep(s))) {
      (void)unwrap(resolve_spec(e));  // every spec valid before the first (long) run, as `btfc bench`
      out.push_back(e);
    }
  }
  if (out.empty()) throw_status(invalid_argument("bench: no spec given"));
  return out;
}

// One row as `btfc bench --json` prints it (cli/bench.cpp), with Python's None for a value the
// CLI prints as null.
py::dict bench_row(const std::string& label, const BenchResult& b, bool renders) {
  auto num = [](double v) -> py::object { return std::isfinite(v) ? py::object(py::float_(v)) : py::object(py::none()); };
  py::dict d;
  d["data"] = label;
  d["spec_given"] = b.spec_given;
  d["spec"] = b.spec;
  d["payload_bytes"] = b.payload_bytes;
  d["file_bytes"] = b.file_bytes;
  d["ratio"] = b.ratio;
  d["bits_per_value"] = b.bits_per_value;
  d["rmse"] = b.metrics.rmse;
  d["rel_l2"] = num(b.metrics.rel_l2);
  d["psnr"] = num(b.metrics.psnr);
  d["psnr_peak"] = b.metrics.peak;
  d["mean_ssim"] = b.metrics.mean_ssim;
  d["render_ssim"] = renders ? py::object(py::float_(b.render_ssim)) : py::object(py::none());
  d["encode_seconds"] = b.encode_seconds;
  d["decode_seconds"] = b.decode_seconds;
  d["evals_per_second"] = b.evals_per_second;
  d["peak_rss_mb"] = double(b.peak_rss_bytes) / (1 << 20);
  d["tensor_digest"] = b.tensor_digest;
  d["device"] = b.device;
  return d;
}

}  // namespace

PYBIND11_MODULE(btfc, m) {
  m.doc() =
      "btfc: compression of Bidirectional Texture Functions (BTFs) on numpy arrays.\n\n"
      "The CLI's data model: btfc.open reads every input `btfc` reads (UBO2003 / UTIA image sets,\n"
      "Bonn .btf, .btfc raw or model); codecs are chosen by the same spec strings (\"fmf:rank=32\");\n"
      "metrics and bench rows are the CLI's. A Btf's values are a zero-copy numpy view of shape\n"
      "(height, width, views, lights, channels), float32. Errors raise btfc.Error.\n\n"
      "    import btfc\n"
      "    btf = btfc.open('textile_lurex_utia64')\n"
      "    model = btfc.compress(btf, 'fmf:rank=16')\n"
      "    model.save('textile.btfc')\n"
      "    print(btfc.compare(btf, model.decode()))\n";
  m.attr("__version__") = BTFC_VERSION;
  register_errors(m);
  bind_btf(m);
  bind_model(m);

  m.def(
      "open",
      [](const std::string& path, const std::string& format) {
        Result<Btf> r = unsupported("open");
        {
          py::gil_scoped_release nogil;
          auto input = open_input(path, format);
          r = input.ok() ? input.value()->read() : Result<Btf>(input.status());
        }
        return PyBtf{std::make_shared<Btf>(unwrap(std::move(r)))};
      },
      py::arg("path"), py::arg("format") = "",
      "Reads any input the CLI reads: a UBO2003 / UTIA image-set directory, a Bonn .btf, a .btfc\n"
      "(raw data, or a model, which is decoded). `format` names a reader ('image-set', 'bonn',\n"
      "'btfc') instead of probing. Returns a Btf; non-finite values are an error.");
  m.def(
      "load",
      [](const std::string& path) {
        Result<std::unique_ptr<Model>> r = unsupported("load");
        {
          py::gil_scoped_release nogil;
          r = open_model(path);
        }
        return PyModel(std::shared_ptr<Model>(unwrap(std::move(r))));
      },
      py::arg("path"), "Opens a model: a .btfc written by any codec, or a Bonn .btf file (FMF / DFMF).");
  m.def(
      "compress",
      [](PyBtf& btf, const std::string& spec, std::optional<double> max_bytes, std::optional<double> target_psnr,
         std::optional<double> target_ssim, uint64_t seed, const py::object& progress, bool consume) {
        const int targets = int(max_bytes.has_value()) + int(target_psnr.has_value()) + int(target_ssim.has_value());
        if (targets > 1) throw_status(invalid_argument("compress: give at most one of max_bytes, target_psnr, target_ssim"));
        if (consume && targets > 0)
          throw_status(invalid_argument("compress: consume=True cannot be combined with max_bytes, target_psnr or target_ssim (the "
                                        "search encodes and compares against the values several times)"));
        const std::shared_ptr<Btf> input = btf.live();
        ProgressBridge bridge(progress);
        Context ctx;
        ctx.seed = seed;
        ctx.progress = bridge.progress();
        py::dict target;
        std::unique_ptr<Model> model;
        if (targets == 1) {
          Target t;
          t.kind = max_bytes ? Target::Kind::max_bytes : target_psnr ? Target::Kind::psnr : Target::Kind::ssim;
          t.value = max_bytes ? *max_bytes : target_psnr ? *target_psnr : *target_ssim;
          Result<TargetChoice> r = unsupported("compress");
          {
            py::gil_scoped_release nogil;
            r = choose_for_target(*input, spec, t, ctx);
          }
          bridge.rethrow();
          TargetChoice c = unwrap(std::move(r));
          target["knob"] = c.knob;
          target["value"] = c.knob_value;
          target["reached"] = c.measure;
          py::list probes;
          for (const TargetProbe& p : c.probes) probes.append(py::dict(py::arg("knob") = p.knob, py::arg("measure") = p.measure, py::arg("meets") = p.meets));
          target["probes"] = probes;
          if (c.knob_limit > 0) target["knob_limit"] = c.knob_limit;
          model = std::move(c.model);
        } else {
          auto [codec, params] = unwrap(resolve_spec(spec));
          Result<std::unique_ptr<Model>> r = unsupported("compress");
          // consume=True: as `btfc compress` lets it, the encode may work in the values' own
          // memory (fmf color=dfmf converts them in place: less memory and time). The Btf is
          // consumed whatever the outcome (a failed encode may have changed the values), and
          // released here: arrays taken from it earlier keep the memory, with unspecified values.
          if (consume) ctx.consumable = input.get();
          {
            py::gil_scoped_release nogil;
            r = codec->encode(*input, params, ctx);
          }
          if (consume) btf.consumed = true, btf.btf.reset();
          bridge.rethrow();
          model = unwrap(std::move(r));
        }
        PyModel out(std::shared_ptr<Model>(std::move(model)));
        out.target = target;
        return out;
      },
      py::arg("btf"), py::arg("spec") = "fmf", py::kw_only(), py::arg("max_bytes") = py::none(), py::arg("target_psnr") = py::none(),
      py::arg("target_ssim") = py::none(), py::arg("seed") = 1, py::arg("progress") = py::none(), py::arg("consume") = false,
      "Compresses a Btf with a spec string ('fmf:rank=32', 'lpca', 'mlvq:scheme=2', ...; unknown\n"
      "parameters are errors). At most one target: max_bytes (the most accurate setting whose\n"
      ".btfc file, model.file_bytes, fits), target_psnr (dB) or target_ssim (mean SSIM): the codec's quality knob is\n"
      "searched as `btfc compress --max-bytes/--target-psnr/--target-ssim` does, and the chosen\n"
      "setting is in model.target. The same seed gives the same model as the CLI's --seed.\n"
      "consume=True hands the values over, as `btfc compress` does with its input: the encode may\n"
      "work in their memory (fmf color=dfmf then converts in place, with less memory and time), and\n"
      "the Btf cannot be used afterwards (its arrays taken earlier hold unspecified values). Not\n"
      "with a target.");
  m.def(
      "compare",
      [](const PyBtf& a, const PyBtf& b, bool ssim) {
        Result<Metrics> r = unsupported("compare");
        const std::shared_ptr<Btf>&ra = a.live(), &rb = b.live();  // with the GIL: they may raise
        {
          py::gil_scoped_release nogil;
          r = compare_btf(*ra, *rb, ssim);
        }
        return metrics_dict(unwrap(std::move(r)));
      },
      py::arg("reference"), py::arg("test"), py::arg("ssim") = true,
      "Error metrics of `test` against `reference` (same shape), as `btfc compare`: rmse, rel_l2,\n"
      "psnr (dB; inf when identical) and the psnr_peak it used, mean_ssim (luminance SSIM per\n"
      "image, per-image range on HDR data: core/metrics.h) and max_abs.");
  m.def(
      "bench",
      [](const PyBtf& btf, const py::object& specs, bool renders, uint64_t seed, size_t throughput_queries, const std::string& label,
         const py::object& progress) {
        const std::vector<std::string> list = spec_list(specs);
        const std::shared_ptr<Btf>& input = btf.live();  // with the GIL: it may raise
        ProgressBridge bridge(progress);
        std::vector<RgbImage> refs;
        py::list rows;
        if (renders) {
          Result<std::vector<RgbImage>> r = unsupported("bench");
          {
            py::gil_scoped_release nogil;
            r = reference_renders(*input);
          }
          refs = unwrap(std::move(r));
        }
        for (const std::string& spec : list) {
          BenchOptions opt;
          opt.seed = seed;
          opt.renders = renders;
          opt.references = renders ? &refs : nullptr;
          opt.throughput_queries = throughput_queries;
          opt.progress = bridge.progress();
          Result<BenchResult> r = unsupported("bench");
          {
            py::gil_scoped_release nogil;
            r = run_benchmark(*input, spec, opt);
          }
          bridge.rethrow();
          rows.append(bench_row(label, unwrap(std::move(r)), renders));
        }
        return rows;
      },
      py::arg("btf"), py::arg("specs"), py::kw_only(), py::arg("renders") = true, py::arg("seed") = 1,
      py::arg("throughput_queries") = size_t(1) << 17, py::arg("label") = "", py::arg("progress") = py::none(),
      "Runs `btfc bench` on a Btf: specs is one spec string or a list, each may sweep\n"
      "('fmf:rank=4,8,16'). Returns one dict per run with the keys of `btfc bench --json` rows:\n"
      "data, spec_given, spec, payload_bytes, file_bytes, ratio (float32 bytes / payload bytes),\n"
      "bits_per_value, rmse, rel_l2, psnr, psnr_peak, mean_ssim, render_ssim (None without\n"
      "renders), encode_seconds, decode_seconds, evals_per_second, peak_rss_mb, tensor_digest, device.");
  m.def("codecs", &codecs_list,
        "The registered codecs: name, summary, payload_version, exporter (has a GPU export),\n"
        "streaming (compresses out of core) and params (name, type, default, min/max or choices,\n"
        "help, quality_knob), as `btfc codecs` lists them.");
  m.def(
      "synth",
      [](int width, int height, uint64_t seed, float bump, float scale, float noise) {
        SynthOptions o;
        o.width = width;
        o.height = height;
        o.seed = seed;
        o.bump = bump;
        o.scale = scale;
        o.noise = noise;
        Result<Btf> r = unsupported("synth");
        {
          py::gil_scoped_release nogil;
          r = synthesize_btf(o);
        }
        return PyBtf{std::make_shared<Btf>(unwrap(std::move(r)))};
      },
      py::arg("width") = 32, py::arg("height") = 32, py::kw_only(), py::arg("seed") = 1, py::arg("bump") = 1.0f, py::arg("scale") = 1.0f,
      py::arg("noise") = 0.0f,
      "The synthetic material of `btfc synth` (UBO2003 81 x 81 directions): the same options give\n"
      "the same values as the CLI.");
  m.def(
      "set_device",
      [](const std::string& choice) { ocl::set_device_choice(unwrap(ocl::parse_device_choice(choice))); },
      py::arg("choice"),
      "Where kernels run, for the whole process, as the CLI's --device: 'auto' (OpenCL when a\n"
      "device is present, else the C++ reference, said once on stderr), 'cpu' (never loads\n"
      "OpenCL) or 'cl' (an error when no device). BTFC_FORCE_CPU=1 in the environment = 'cpu'.");
  m.def(
      "device",
      []() {
        py::gil_scoped_release nogil;
        return ocl::device_summary();
      },
      "Where kernels run now (the device bench rows report).");
  m.def(
      "set_memory_limit", [](size_t bytes) { set_memory_limit(bytes); }, py::arg("bytes"),
      "The largest allocation btfc makes for a BTF or a decode (BTFC_MAX_MEMORY; a larger one is\n"
      "an error before allocating).");
  m.def("machine", &machine_summary, "The machine summary bench reports carry (CPU, cores, memory, BLAS).");
}
