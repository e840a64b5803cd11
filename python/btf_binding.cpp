// btfc.Btf: a BTF's values as a zero-copy numpy view, its direction sets, and the errors and
// progress bridge the module's calls share (btfc_python.h).
#include <pybind11/stl.h>

#include <algorithm>
#include <cmath>
#include <cstring>

#include "btfc_python.h"
#include "formats/btf_io.h"

namespace btfc::python {

void register_errors(py::module_& m) {
  // Created once, kept for the interpreter's life (not destroyed at exit, after Python is gone).
  static py::handle error_type = py::exception<StatusError>(m, "Error", PyExc_RuntimeError).release();
  error_type.attr("__doc__") =
      "A btfc error: the message names the file and the problem, as the CLI prints it; `code` is\n"
      "its kind: invalid_argument, unsupported, corrupt_data, io_error, codec_error or device_error.";
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const StatusError& e) {
      py::object err = error_type(e.what());
      err.attr("code") = e.code;
      PyErr_SetObject(error_type.ptr(), err.ptr());
    }
  });
}

ProgressBridge::ProgressBridge(py::object callback) : m_callback(std::move(callback)) {
  if (m_callback.is_none()) return;
  if (!PyCallable_Check(m_callback.ptr())) throw_status(invalid_argument("progress: expected a callable (stage, done, total)"));
  m_progress = std::make_unique<Progress>([this](const std::string& label, uint64_t done, uint64_t total) {
    py::gil_scoped_acquire gil;
    if (m_error) return;
    try {
      m_callback(label, done, total);
    } catch (...) {
      m_error = std::current_exception();
    }
  });
}

void ProgressBridge::rethrow() {
  if (m_progress) m_progress->finish();
  if (m_error) std::rethrow_exception(std::exchange(m_error, nullptr));
}

const std::shared_ptr<Btf>& PyBtf::live() const {
  if (consumed)
    throw_status(invalid_argument("this btfc.Btf was consumed by compress(consume=True): its values are gone; open or build it again"));
  return btf;
}

py::array values_view(const PyBtf& b) {
  const std::shared_ptr<Btf>& btf = b.live();
  const BtfDesc& d = btf->desc();
  auto* owner = new std::shared_ptr<Btf>(btf);
  py::capsule base(owner, [](void* p) { delete static_cast<std::shared_ptr<Btf>*>(p); });
  const std::vector<py::ssize_t> shape{d.height, d.width, py::ssize_t(d.num_views()), py::ssize_t(d.num_lights()), d.channels};
  std::vector<py::ssize_t> strides(5);
  py::ssize_t s = sizeof(float);
  for (int i = 4; i >= 0; --i) {
    strides[size_t(i)] = s;
    s *= shape[size_t(i)];
  }
  return py::array_t<float>(shape, strides, btf->data(), base);
}

py::array directions_array(const DirectionSet& set) {
  py::array_t<float> a({py::ssize_t(set.size()), py::ssize_t(3)});
  auto w = a.mutable_unchecked<2>();
  for (size_t i = 0; i < set.size(); ++i) {
    w(py::ssize_t(i), 0) = set.dirs[i].x;
    w(py::ssize_t(i), 1) = set.dirs[i].y;
    w(py::ssize_t(i), 2) = set.dirs[i].z;
  }
  return a;
}

namespace {

// "ubo2003" / "ubo2014" or an (n, 3) array of directions (normalized here).
DirectionSet direction_set(const py::object& o, const char* what) {
  if (py::isinstance<py::str>(o)) {
    const std::string name = o.cast<std::string>();
    if (name == "ubo2003") return DirectionSet::ubo2003();
    if (name == "ubo2014") return DirectionSet::ubo2014();
    throw_status(invalid_argument(std::string(what) + ": unknown direction set '" + name + "' (ubo2003, ubo2014 or an (n, 3) array)"));
  }
  auto a = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(o);
  if (!a || a.ndim() != 2 || a.shape(1) != 3 || a.shape(0) < 1)
    throw_status(invalid_argument(std::string(what) + ": expected an (n, 3) array of direction vectors"));
  DirectionSet set;
  auto r = a.unchecked<2>();
  for (py::ssize_t i = 0; i < r.shape(0); ++i) {
    const double x = r(i, 0), y = r(i, 1), z = r(i, 2), n = std::sqrt(x * x + y * y + z * z);
    if (!std::isfinite(n) || n <= 0)
      throw_status(invalid_argument(std::string(what) + ": direction " + std::to_string(i) + " is zero or not finite"));
    set.dirs.push_back(Vec3{float(x / n), float(y / n), float(z / n)});
  }
  set.identify();
  return set;
}

PyBtf make_btf(const py::array& data_in, const py::object& lights, const py::object& views, const py::object& hdr) {
  auto data = py::array_t<float, py::array::c_style | py::array::forcecast>::ensure(data_in);
  if (!data || data.ndim() != 5)
    throw_status(invalid_argument("btfc.Btf: data must be a 5-d array (height, width, views, lights, channels)"));
  BtfDesc d;
  d.height = int(data.shape(0));
  d.width = int(data.shape(1));
  d.channels = int(data.shape(4));
  d.lights = direction_set(lights, "lights");
  d.views = direction_set(views, "views");
  if (py::ssize_t(d.num_views()) != data.shape(2) || py::ssize_t(d.num_lights()) != data.shape(3))
    throw_status(invalid_argument("btfc.Btf: data has " + std::to_string(data.shape(2)) + " views x " + std::to_string(data.shape(3)) +
                                  " lights, the direction sets " + std::to_string(d.num_views()) + " x " + std::to_string(d.num_lights())));
  const float* src = data.data();
  const size_t n = size_t(data.size());
  d.hdr = hdr.is_none() ? std::any_of(src, src + n, [](float v) { return v > 1.0f; }) : hdr.cast<bool>();
  auto btf = std::make_shared<Btf>(unwrap(Btf::create(d)));
  std::memcpy(btf->data(), src, n * sizeof(float));
  check(btf->check_finite("btfc.Btf data"));
  return PyBtf{btf};
}

}  // namespace

void bind_btf(py::module_& m) {
  py::class_<PyBtf>(m, "Btf",
                    "A BTF: per texel, light and view direction, `channels` linear float values.\n\n"
                    "`data` is a zero-copy view of btfc's buffer, shape (height, width, views, lights,\n"
                    "channels), float32: data[y, x, v, l, c] is texel (x, y) under light l seen from\n"
                    "view v (btfc's pinned texel-major layout, docs/FORMAT.md). `lights` and `views` are\n"
                    "(n, 3) unit vectors in the sample's frame (z = normal).")
      .def(py::init(&make_btf), py::arg("data"), py::arg("lights") = "ubo2003", py::arg("views") = "ubo2003", py::arg("hdr") = py::none(),
           "A BTF from an array of shape (height, width, views, lights, channels), copied once.\n"
           "lights / views: 'ubo2003', 'ubo2014' or (n, 3) direction arrays. hdr: None = any value > 1.")
      .def_property_readonly("data", &values_view, "The values, (height, width, views, lights, channels) float32, a view (no copy).")
      .def("__array__", [](const PyBtf& b, const py::object& dtype) {
             py::array v = values_view(b);
             return dtype.is_none() ? v : py::array(v.attr("astype")(dtype));
           }, py::arg("dtype") = py::none())
      .def_property_readonly("lights", [](const PyBtf& b) { return directions_array(b.live()->desc().lights); }, "(lights, 3) unit vectors.")
      .def_property_readonly("views", [](const PyBtf& b) { return directions_array(b.live()->desc().views); }, "(views, 3) unit vectors.")
      .def_property_readonly("lights_name", [](const PyBtf& b) { return b.live()->desc().lights.name; }, "'ubo2003', 'ubo2014' or 'custom'.")
      .def_property_readonly("views_name", [](const PyBtf& b) { return b.live()->desc().views.name; })
      .def_property_readonly("width", [](const PyBtf& b) { return b.live()->desc().width; })
      .def_property_readonly("height", [](const PyBtf& b) { return b.live()->desc().height; })
      .def_property_readonly("channels", [](const PyBtf& b) { return b.live()->desc().channels; })
      .def_property_readonly("hdr", [](const PyBtf& b) { return b.live()->desc().hdr; }, "Linear HDR values (PSNR peak and SSIM range rules, core/metrics.h).")
      .def_property_readonly("shape", [](const PyBtf& b) { return values_view(b).attr("shape"); })
      .def(
          "image",
          [](const PyBtf& b, int light, int view) {
            const std::shared_ptr<Btf>& btf = b.live();
            const BtfDesc& d = btf->desc();
            if (light < 0 || size_t(light) >= d.num_lights() || view < 0 || size_t(view) >= d.num_views())
              throw_status(invalid_argument("image: light " + std::to_string(light) + ", view " + std::to_string(view) + " outside " +
                                            std::to_string(d.num_lights()) + " lights x " + std::to_string(d.num_views()) + " views"));
            // data[:, :, view, light, :] as its own strided view of the buffer.
            auto* owner = new std::shared_ptr<Btf>(btf);
            py::capsule base(owner, [](void* p) { delete static_cast<std::shared_ptr<Btf>*>(p); });
            const py::ssize_t f = sizeof(float), texel = py::ssize_t(d.abrdf_size()) * f;
            return py::array_t<float>({py::ssize_t(d.height), py::ssize_t(d.width), py::ssize_t(d.channels)},
                                      {texel * d.width, texel, f}, btf->data() + d.row(size_t(light), size_t(view), 0), base);
          },
          py::arg("light"), py::arg("view"), "One (light, view) image, (height, width, channels): a strided view.")
      .def(
          "save",
          [](const PyBtf& b, const std::string& path, const std::string& image_format) {
            ImageFormat f = ImageFormat::exr;
            if (image_format == "png") f = ImageFormat::png;
            else if (image_format != "exr") throw_status(invalid_argument("save: image_format must be 'exr' or 'png'"));
            const std::shared_ptr<Btf>& btf = b.live();  // with the GIL: it may raise
            py::gil_scoped_release nogil;
            check(write_btf(*btf, path, f));
          },
          py::arg("path"), py::arg("image_format") = "exr",
          "Writes the raw BTF: a .btfc container, or else an image-set directory (UBO2003 names).")
      .def("__repr__", [](const PyBtf& b) {
        if (b.consumed) return std::string("<btfc.Btf, consumed by compress(consume=True)>");
        return "<btfc.Btf " + b.btf->desc().summary() + (b.btf->desc().hdr ? ", HDR" : "") + ">";
      });
}

}  // namespace btfc::python
