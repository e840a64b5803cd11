// Readers: every input btfc takes, probed once and opened once (one table, formats/reader.cpp).
//
//   name        probe (cheap)                          opens as
//   image-set   a directory                            UBO2003 / UTIA image set (formats/image_set.h), planned once
//   bonn        a Bonn signature (10 bytes)            DFMF / FMF / PVF / BDI (formats/bonn/bonn_btf.h): a model
//   btfc        the container magic                    raw data (codec "raw": values read on demand) or a model
//
// open_input tries them in this order (an explicit `format` names one; a file no probe accepts is
// opened as a container, whose error then says what is wrong: magic, truncation); read_btf,
// open_model and probe_btf (formats/btf_io.h, btf_stream.h) are open_input plus one call.
// Errors name the path.
#pragma once
#include <memory>
#include <span>
#include <string>

#include "codecs/codec.h"
#include "core/btf.h"

namespace btfc {

struct ImageSetPlan;  // formats/image_set.h

// An opened input: its shape is known; its values are read on demand.
class BtfInput {
 public:
  virtual ~BtfInput() = default;
  virtual const char* format() const = 0;      // the reader's name
  virtual const std::string& path() const = 0;
  virtual const BtfDesc& desc() const = 0;
  // The whole BTF (a model input decoded). Finite values are checked.
  virtual Result<Btf> read() = 0;
  // The model, when the input is one (a model .btfc, a Bonn file), else null.
  virtual const Model* model() const { return nullptr; }
  // Hands the model over (the input no longer has it); an error naming the path for raw data.
  virtual Result<std::unique_ptr<Model>> take_model() = 0;
  // The plan an image set was opened with (its files, order, shape), else null: bounded-memory
  // readers (formats/btf_stream.h) read its images in groups without planning it again.
  virtual const ImageSetPlan* image_set_plan() const { return nullptr; }
};

struct BtfReader {
  const char* name;
  const char* what;  // one line for help and errors
  bool (*probe)(const std::string& path);
  Result<std::unique_ptr<BtfInput>> (*open)(const std::string& path);
};

std::span<const BtfReader> btf_readers();
// The first reader whose probe accepts `path`, or null (for format-specific reports: `btfc info`).
const BtfReader* find_reader(const std::string& path);
// Opens `path` with the first reader whose probe accepts it, or with the reader named `format`.
// A missing path is "PATH: no such file or directory"; a file no reader accepts is corrupt_data
// naming the readers tried.
Result<std::unique_ptr<BtfInput>> open_input(const std::string& path, const std::string& format = "");

}  // namespace btfc
