// What the Python module's files share: errors as btfc.Error, the Btf and Model wrappers and the
// progress bridge. (The module: btfc_module.cpp; Btf: btf_binding.cpp; Model: model_binding.cpp.)
#pragma once
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <exception>
#include <memory>
#include <stdexcept>
#include <string>

#include "codecs/codec.h"
#include "core/btf.h"
#include "core/progress.h"
#include "core/status.h"

namespace btfc::python {

namespace py = pybind11;

// A btfc Status on its way to Python: translated to btfc.Error(message) with .code set.
struct StatusError : std::runtime_error {
  StatusError(const Status& s) : std::runtime_error(s.message()), code(code_name(s.code())) {}
  std::string code;
  // As an identifier (status_code_name's words are for people: "i/o error").
  static const char* code_name(StatusCode c) {
    switch (c) {
      case StatusCode::ok: return "ok";
      case StatusCode::invalid_argument: return "invalid_argument";
      case StatusCode::unsupported: return "unsupported";
      case StatusCode::corrupt_data: return "corrupt_data";
      case StatusCode::io_error: return "io_error";
      case StatusCode::codec_error: return "codec_error";
      case StatusCode::device_error: return "device_error";
    }
    return "unknown";
  }
};
[[noreturn]] inline void throw_status(const Status& s) { throw StatusError(s); }
template <class T>
T unwrap(Result<T>&& r) {
  if (!r.ok()) throw_status(r.status());
  return std::move(r).value();
}
inline void check(const Status& s) {
  if (!s.ok()) throw_status(s);
}
void register_errors(py::module_& m);

// A BTF shared between Python objects: the numpy views of its values keep it alive.
struct PyBtf {
  std::shared_ptr<Btf> btf;
  bool consumed = false;  // compress(consume=True) took the values (btf is then null)
  // The BTF, or a btfc.Error when compress(consume=True) has taken it.
  const std::shared_ptr<Btf>& live() const;
};

struct PyModel {
  explicit PyModel(std::shared_ptr<Model> m) : model(std::move(m)) {}
  std::shared_ptr<Model> model;
  py::dict target;  // the byte-budget / quality-target search's choice (compress with a target)
};

// A Progress whose updates go to a Python callable (or none when it is None). The callable is
// called with the GIL acquired; its first exception stops further calls and is re-raised by
// rethrow() once the C++ call has returned.
class ProgressBridge {
 public:
  explicit ProgressBridge(py::object callback);
  Progress* progress() { return m_progress.get(); }
  void rethrow();

 private:
  py::object m_callback;
  std::exception_ptr m_error;
  std::unique_ptr<Progress> m_progress;  // last: destroyed (its final update sent) first
};

void bind_btf(py::module_& m);
void bind_model(py::module_& m);
// The numpy view of a Btf's values, shape (height, width, views, lights, channels).
py::array values_view(const PyBtf& b);
// Directions as an (n, 3) float32 array.
py::array directions_array(const DirectionSet& set);

}  // namespace btfc::python
