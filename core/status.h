// Status / Result: btfc's error model. No exception crosses the library boundary;
// every fallible call returns a Status (code + message) or a Result<T> (value or Status).
// Messages name the file and the field at fault, e.g. "carpet.btfc: chunk TNSR 'U': size 12 exceeds file".
#pragma once
#include <string>
#include <utility>
#include <variant>

namespace btfc {

enum class StatusCode {
  ok = 0,
  invalid_argument,  // bad parameter or usage (CLI exit 1)
  unsupported,       // valid input btfc cannot handle
  corrupt_data,      // file content disagrees with itself (CLI exit 2)
  io_error,          // open/read/write failed (CLI exit 2)
  codec_error,       // a codec failed on valid input (CLI exit 3)
  device_error,      // OpenCL device failure (CLI exit 3)
};

const char* status_code_name(StatusCode c);

class [[nodiscard]] Status {
 public:
  Status() = default;
  Status(StatusCode code, std::string message) : m_code(code), m_message(std::move(message)) {}
  static Status ok_status() { return {}; }
  bool ok() const { return m_code == StatusCode::ok; }
  StatusCode code() const { return m_code; }
  const std::string& message() const { return m_message; }
  // Prefixes context ("file.btfc: ") so low-level errors end up naming the file.
  Status with_context(const std::string& prefix) const {
    return ok() ? *this : Status(m_code, prefix + ": " + m_message);
  }

 private:
  StatusCode m_code = StatusCode::ok;
  std::string m_message;
};

inline Status invalid_argument(std::string m) { return {StatusCode::invalid_argument, std::move(m)}; }
inline Status unsupported(std::string m) { return {StatusCode::unsupported, std::move(m)}; }
inline Status corrupt_data(std::string m) { return {StatusCode::corrupt_data, std::move(m)}; }
inline Status io_error(std::string m) { return {StatusCode::io_error, std::move(m)}; }
inline Status codec_error(std::string m) { return {StatusCode::codec_error, std::move(m)}; }

template <class T>
class [[nodiscard]] Result {
 public:
  Result(T value) : m_v(std::move(value)) {}
  Result(Status status) : m_v(std::move(status)) {}
  bool ok() const { return std::holds_alternative<T>(m_v); }
  const Status& status() const {
    static const Status k_ok;
    return ok() ? k_ok : std::get<Status>(m_v);
  }
  T& value() & { return std::get<T>(m_v); }
  const T& value() const& { return std::get<T>(m_v); }
  // By value: `for (auto& x : make().value())` must not bind to a dying temporary's member.
  T value() && { return std::get<T>(std::move(m_v)); }
  T& operator*() & { return value(); }
  const T& operator*() const& { return value(); }
  T* operator->() { return &value(); }
  const T* operator->() const { return &value(); }

 private:
  std::variant<T, Status> m_v;
};

}  // namespace btfc

#define BTFC_CONCAT_INNER(a, b) a##b
#define BTFC_CONCAT(a, b) BTFC_CONCAT_INNER(a, b)

#define BTFC_RETURN_IF_ERROR(expr)              \
  do {                                          \
    ::btfc::Status btfc_status_ = (expr);       \
    if (!btfc_status_.ok()) return btfc_status_; \
  } while (0)

// BTFC_ASSIGN_OR_RETURN(auto x, make_x()); declares x from a Result or returns its Status.
#define BTFC_ASSIGN_OR_RETURN(lhs, expr) \
  BTFC_ASSIGN_OR_RETURN_IMPL(BTFC_CONCAT(btfc_result_, __LINE__), lhs, expr)
#define BTFC_ASSIGN_OR_RETURN_IMPL(tmp, lhs, expr) \
  auto tmp = (expr);                               \
  if (!tmp.ok()) return tmp.status();              \
  lhs = std::move(tmp).value()
