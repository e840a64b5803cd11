#include "core/status.h"

namespace btfc {

const char* status_code_name(StatusCode c) {
  switch (c) {
    case StatusCode::ok: return "ok";
    case StatusCode::invalid_argument: return "invalid argument";
    case StatusCode::unsupported: return "unsupported";
    case StatusCode::corrupt_data: return "corrupt data";
    case StatusCode::io_error: return "i/o error";
    case StatusCode::codec_error: return "codec error";
    case StatusCode::device_error: return "device error";
  }
  return "unknown";
}

}  // namespace btfc
