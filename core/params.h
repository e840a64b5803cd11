// Codec parameters and spec strings ("fmf:rank=32:precision=half").
//
// Every parameter has a type, a default, a range (or a list of choices) and a help line.
// Binding a spec string to a codec's ParamSpec table rejects unknown keys, repeated keys,
// malformed numbers and out-of-range values (the pbrt-v4 ReportUnused rule): a typo is an
// error, never a silently ignored setting. The canonical spec (every key, in table order)
// is what .btfc files store, so a model records exactly how it was made.
#pragma once
#include <map>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "core/status.h"

namespace btfc {

struct ParamSpec {
  enum class Type { integer, real, choice };
  std::string name;
  Type type = Type::integer;
  std::string default_value;
  double min = 0, max = 0;            // inclusive; integer and real only
  std::vector<std::string> choices;   // choice only
  std::string help;
  // The codec's one quality knob (larger = more accurate, more bytes): what budget targeting
  // (codecs/target.h) searches and sweeps are usually over. At most one per codec.
  bool quality_knob = false;
};

// "codec:key=value:key=value" split into its parts; no validation beyond syntax.
struct SpecString {
  std::string codec;
  std::vector<std::pair<std::string, std::string>> values;
};
Result<SpecString> parse_spec_string(std::string_view text);

// Validated parameter values for one codec; every key of the table is present.
class Params {
 public:
  long long get_int(const std::string& name) const;
  double get_real(const std::string& name) const;
  const std::string& get(const std::string& name) const;
  bool was_set(const std::string& name) const { return m_set.count(name) != 0; }
  // "codec:k=v:..." with all keys in table order.
  const std::string& canonical() const { return m_canonical; }

 private:
  friend Result<Params> bind_params(const SpecString&, std::span<const ParamSpec>);
  std::map<std::string, std::string> m_values;
  std::map<std::string, bool> m_set;
  std::string m_canonical;
};

Result<Params> bind_params(const SpecString& spec, std::span<const ParamSpec> table);

// `p` with `key` set to `value` (re-bound, so the value is checked against the table and the
// key counts as set): how a codec records the value it used when it differs from the one asked
// for (a rank clamped to the data's size, an offset taken from the data).
Result<Params> with_value(const Params& p, const std::string& key, const std::string& value, std::span<const ParamSpec> table);

// One line per parameter: "  rank  int [1, 4096] default 32  -- help".
std::string describe_params(std::span<const ParamSpec> table);

// A real value for a message: "%.6g" (std::to_string's fixed "%f" shows 1.2e-07 as 0.000000).
std::string real_string(double v);

}  // namespace btfc
