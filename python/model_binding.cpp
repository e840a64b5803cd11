// btfc.Model: a compressed BTF (any codec): save, decode a region or direction subset,
// vectorized evaluation at measured or arbitrary directions, statistics, GPU export.
#include <pybind11/stl.h>

#include <cmath>
#include <nlohmann/json.hpp>

#include "btfc_python.h"
#include "codecs/gpu_export.h"
#include "formats/bsvtf/bsvtf_export.h"
#include "formats/btf_io.h"
#include "formats/gpu/export.h"

namespace btfc::python {

namespace {

std::string codec_name(const Model& m) {
  const std::string& s = m.spec();
  return s.substr(0, s.find(':'));
}

const Codec& codec_of(const Model& m) {
  const Codec* c = find_codec(codec_name(m));
  if (!c) throw_status(unsupported(m.spec() + ": no registered codec"));
  return *c;
}

std::vector<int> index_list(const py::object& o, size_t n, const char* what) {
  std::vector<int> out;
  if (o.is_none()) return out;
  auto a = py::array_t<long long, py::array::c_style | py::array::forcecast>::ensure(o);
  if (!a || a.ndim() > 1) throw_status(invalid_argument(std::string(what) + ": expected a list of indices"));
  for (py::ssize_t i = 0; i < a.size(); ++i) {
    const long long v = a.data()[i];
    if (v < 0 || size_t(v) >= n)
      throw_status(invalid_argument(std::string(what) + ": index " + std::to_string(v) + " outside 0.." + std::to_string(n - 1)));
    out.push_back(int(v));
  }
  if (out.empty()) throw_status(invalid_argument(std::string(what) + ": an empty list selects nothing (None = all)"));
  return out;
}

PyBtf decode(const PyModel& pm, const py::object& region, const py::object& lights, const py::object& views, double lod) {
  const BtfDesc& d = pm.model->desc();
  DecodeRequest req;
  if (!region.is_none()) {
    auto r = region.cast<std::vector<int>>();
    if (r.size() != 4) throw_status(invalid_argument("decode: region is (x0, y0, width, height)"));
    req.x0 = r[0];
    req.y0 = r[1];
    req.width = r[2];
    req.height = r[3];
  }
  req.lights = index_list(lights, d.num_lights(), "lights");
  req.views = index_list(views, d.num_views(), "views");
  req.lod = lod;
  auto out = std::make_shared<Btf>();
  Status s;
  {
    py::gil_scoped_release nogil;
    s = pm.model->decode(req, *out);
  }
  check(s);
  return PyBtf{out};
}

// One argument of eval: measured indices (integers, shape (n,) or scalar) or directions
// (floats, shape (n, 3) or (3,)). Returns the rows (1 = broadcast) and fills one of the lists.
struct DirArg {
  bool indices = false;
  std::vector<int> idx;
  std::vector<Vec3> dirs;
  size_t rows() const { return indices ? idx.size() : dirs.size(); }
};

DirArg dir_arg(const py::object& o, const char* what) {
  DirArg a;
  py::array arr = py::array::ensure(o);
  if (!arr) throw_status(invalid_argument(std::string(what) + ": expected indices or (n, 3) directions"));
  const char kind = arr.dtype().kind();
  if (kind == 'i' || kind == 'u') {
    auto v = py::array_t<long long, py::array::c_style | py::array::forcecast>::ensure(arr);
    if (v.ndim() > 1) throw_status(invalid_argument(std::string(what) + ": measured indices are a 1-d array"));
    a.indices = true;
    for (py::ssize_t i = 0; i < v.size(); ++i) a.idx.push_back(int(v.data()[i]));
    return a;
  }
  auto v = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(arr);
  if (!v || v.ndim() < 1 || v.ndim() > 2 || v.shape(v.ndim() - 1) != 3)
    throw_status(invalid_argument(std::string(what) + ": directions are an (n, 3) array of vectors"));
  for (py::ssize_t i = 0; i < v.size() / 3; ++i) {
    const double* p = v.data() + 3 * i;
    const double n = std::sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
    if (!std::isfinite(n) || n <= 0) throw_status(invalid_argument(std::string(what) + ": direction " + std::to_string(i) + " is zero or not finite"));
    a.dirs.push_back(Vec3{float(p[0] / n), float(p[1] / n), float(p[2] / n)});
  }
  return a;
}

py::array eval(const PyModel& pm, const py::object& texels_in, const py::object& wl_in, const py::object& wv_in, double lod) {
  const Model& model = *pm.model;
  const BtfDesc& d = model.desc();
  auto texels = py::array_t<long long, py::array::c_style | py::array::forcecast>::ensure(texels_in);
  if (!texels || texels.ndim() < 1 || texels.ndim() > 2 || texels.shape(texels.ndim() - 1) != 2)
    throw_status(invalid_argument("eval: texels are an (n, 2) integer array of (x, y)"));
  const DirArg wl = dir_arg(wl_in, "wl"), wv = dir_arg(wv_in, "wv");
  if (wl.indices != wv.indices)
    throw_status(invalid_argument(std::string("eval: give wl and wv both as measured indices (integers) or both as directions (floats, (n, 3)); wl is ") +
                                  (wl.indices ? "integers" : "floats") + ", wv " + (wv.indices ? "integers" : "floats") +
                                  " (a direction written [0, 0, 1] is integers: write [0.0, 0.0, 1.0])"));
  const size_t nt = size_t(texels.size() / 2);
  size_t n = std::max({nt, wl.rows(), wv.rows()});
  for (size_t rows : {nt, wl.rows(), wv.rows()})
    if (rows != n && rows != 1)
      throw_status(invalid_argument("eval: texels, wl and wv have " + std::to_string(nt) + ", " + std::to_string(wl.rows()) + " and " +
                                    std::to_string(wv.rows()) + " rows (each n or 1)"));
  if (lod != 0 && !wl.indices) throw_status(invalid_argument("eval: lod works with measured indices (as `btfc eval --lod`)"));
  std::vector<EvalQuery> q(n);
  bool below = false;
  for (size_t i = 0; i < n; ++i) {
    const long long* t = texels.data() + 2 * (nt == 1 ? 0 : i);
    if (t[0] < 0 || t[1] < 0 || t[0] >= d.width || t[1] >= d.height)
      throw_status(invalid_argument("eval: texel (" + std::to_string(t[0]) + ", " + std::to_string(t[1]) + ") is outside the " +
                                    std::to_string(d.width) + "x" + std::to_string(d.height) + " texels"));
    q[i].x = int(t[0]);
    q[i].y = int(t[1]);
    if (wl.indices) {
      q[i].light = wl.idx[wl.rows() == 1 ? 0 : i];
      q[i].view = wv.idx[wv.rows() == 1 ? 0 : i];
      if (q[i].light < 0 || size_t(q[i].light) >= d.num_lights() || q[i].view < 0 || size_t(q[i].view) >= d.num_views())
        throw_status(invalid_argument("eval: light " + std::to_string(q[i].light) + ", view " + std::to_string(q[i].view) + " outside " +
                                      std::to_string(d.num_lights()) + " lights x " + std::to_string(d.num_views()) + " views"));
    } else {
      q[i].wl = wl.dirs[wl.rows() == 1 ? 0 : i];
      q[i].wv = wv.dirs[wv.rows() == 1 ? 0 : i];
      below = below || q[i].wl.z < 0 || q[i].wv.z < 0;
    }
  }
  // Beyond the measured directions the value is extrapolated: said, as `btfc eval` says it.
  if (below && PyErr_WarnEx(PyExc_RuntimeWarning, "btfc: extrapolated evaluation: a direction below the horizon (z < 0)", 1) < 0)
    throw py::error_already_set();
  const bool single = texels.ndim() == 1 && wl.rows() == 1 && wv.rows() == 1 && py::array::ensure(wl_in).ndim() <= (wl.indices ? 0 : 1);
  py::array_t<float> out({py::ssize_t(n), py::ssize_t(d.channels)});
  float* o = out.mutable_data();
  Status s;
  {
    py::gil_scoped_release nogil;
    if (lod != 0) {
      for (size_t i = 0; i < n && s.ok(); ++i) s = model.eval_lod(q[i].x, q[i].y, q[i].light, q[i].view, lod, o + i * size_t(d.channels));
    } else {
      s = model.eval_batch(q, o);
    }
  }
  check(s);
  if (single) return out.attr("reshape")(d.channels);
  return out;
}

py::dict stats(const PyModel& pm) {
  const ModelStats st = pm.model->stats();
  py::dict out;
  for (const auto& [k, v] : st.numbers) out[py::str(k)] = v;
  for (const auto& [k, v] : st.notes) out[py::str(k)] = v;
  return out;
}

py::object export_dir(const PyModel& pm, const std::string& dir, bool half, bool bsvtf, bool previews) {
  gpu::ExportOptions opt;
  opt.half = half;
  Result<gpu::ExportBundle> bundle = unsupported("export");
  BsvtfReport report;
  Status s;
  {
    py::gil_scoped_release nogil;
    bundle = gpu::build_export(*pm.model, opt);
    if (bundle.ok()) {
      if (bsvtf) attach_bsvtf(bundle.value(), *pm.model, opt, BsvtfOptions{}, &report);
      s = gpu::write_export_dir(bundle.value(), dir, previews);
    }
  }
  if (!bundle.ok()) throw_status(bundle.status());
  check(s);
  nlohmann::json j = gpu::manifest_json(bundle.value());
  j.erase("btf");  // the direction tables: in the manifest file
  j["directory"] = dir;
  return py::module_::import("json").attr("loads")(j.dump());
}

}  // namespace

void bind_model(py::module_& m) {
  py::class_<PyModel>(m, "Model",
                      "A compressed BTF (any codec), from btfc.compress or btfc.load. It decodes, evaluates,\n"
                      "saves and exports itself.")
      .def_property_readonly("spec", [](const PyModel& p) { return p.model->spec(); }, "The canonical spec string (every key) it was made with.")
      .def_property_readonly("codec", [](const PyModel& p) { return codec_name(*p.model); })
      .def_property_readonly("width", [](const PyModel& p) { return p.model->desc().width; })
      .def_property_readonly("height", [](const PyModel& p) { return p.model->desc().height; })
      .def_property_readonly("channels", [](const PyModel& p) { return p.model->desc().channels; })
      .def_property_readonly("hdr", [](const PyModel& p) { return p.model->desc().hdr; })
      .def_property_readonly("lights", [](const PyModel& p) { return directions_array(p.model->desc().lights); }, "(lights, 3) unit vectors.")
      .def_property_readonly("views", [](const PyModel& p) { return directions_array(p.model->desc().views); }, "(views, 3) unit vectors.")
      .def_property_readonly("payload_bytes", [](const PyModel& p) { return p.model->payload_bytes(); }, "Bytes of the stored tensors (bench's ratio).")
      .def_property_readonly(
          "file_bytes", [](const PyModel& p) { return unwrap(model_file_bytes(*p.model, codec_of(*p.model))); },
          "Bytes of the .btfc file save() writes (container framing and statistics included).")
      .def_property_readonly(
          "ratio",
          [](const PyModel& p) {
            return double(p.model->desc().num_values()) * 4.0 / double(unwrap(model_file_bytes(*p.model, codec_of(*p.model))));
          },
          "float32 bytes of the BTF / bytes of the .btfc file, as `btfc compress` and `btfc info` print it.")
      .def_readonly("target", &PyModel::target, "compress with a target: the knob chosen, its value, what it reached, the probes.")
      .def("stats", &stats, "The model's statistics (numbers and notes), as `btfc info` lists them.")
      .def(
          "save",
          [](const PyModel& p, const std::string& path) {
            py::gil_scoped_release nogil;
            check(write_model(*p.model, path));
          },
          py::arg("path"), "Writes the model, atomically: .btfc (any codec) or .btf (Bonn FMF / DFMF, fmf models).")
      .def("decode", &decode, py::arg("region") = py::none(), py::arg("lights") = py::none(), py::arg("views") = py::none(),
           py::arg("lod") = 0.0,
           "Decodes to a Btf: everything, or a texel region (x0, y0, width, height) and subsets of\n"
           "light / view indices (None = all), at a level of detail (lpyr; 0 = full).")
      .def("eval", &eval, py::arg("texels"), py::arg("wl"), py::arg("wv"), py::kw_only(), py::arg("lod") = 0.0,
           "Vectorized evaluation. texels: (n, 2) integers (x, y). wl, wv: measured indices ((n,)\n"
           "integers) or directions ((n, 3) vectors, normalized here; interpolated between the\n"
           "measured ones as `btfc eval --wl/--wv`). Any argument with one row is broadcast.\n"
           "Returns (n, channels) float32; (channels,) for one texel and one direction pair.")
      .def("export", &export_dir, py::arg("directory"), py::kw_only(), py::arg("half") = true, py::arg("bsvtf") = true,
           py::arg("previews") = true,
           "Writes the GPU export of `btfc export`: KTX2 textures, manifest.json, btf.frag (and\n"
           "model.bsvtf for a factorization). Returns the manifest (without its direction tables).")
      .def("__repr__", [](const PyModel& p) { return "<btfc.Model " + p.model->spec() + ", " + p.model->desc().summary() + ">"; });
}

}  // namespace btfc::python
