#include "core/params.h"

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <set>
#include <sstream>

namespace btfc {

Result<SpecString> parse_spec_string(std::string_view text) {
  SpecString out;
  size_t pos = text.find(':');
  out.codec = std::string(text.substr(0, pos));
  if (out.codec.empty()) return invalid_argument("spec '" + std::string(text) + "': missing codec name");
  std::set<std::string> seen;
  while (pos != std::string_view::npos) {
    size_t next = text.find(':', pos + 1);
    std::string_view item = text.substr(pos + 1, next == std::string_view::npos ? std::string_view::npos : next - pos - 1);
    pos = next;
    if (item.empty()) continue;  // tolerate "fmf:" and "a::b"
    size_t eq = item.find('=');
    if (eq == std::string_view::npos || eq == 0 || eq + 1 == item.size())
      return invalid_argument("spec '" + std::string(text) + "': expected key=value, got '" + std::string(item) + "'");
    std::string key(item.substr(0, eq));
    if (!seen.insert(key).second)
      return invalid_argument("spec '" + std::string(text) + "': parameter '" + key + "' given twice");
    out.values.emplace_back(key, std::string(item.substr(eq + 1)));
  }
  return out;
}

static bool parse_number(const std::string& s, bool integer, double& out) {
  errno = 0;
  char* end = nullptr;
  if (integer) {
    long long v = std::strtoll(s.c_str(), &end, 10);
    out = static_cast<double>(v);
  } else {
    out = std::strtod(s.c_str(), &end);
  }
  return errno == 0 && end && *end == '\0' && !s.empty() && std::isfinite(out);
}

static std::string format_number(double v, bool integer) {
  std::ostringstream os;
  if (integer) os << static_cast<long long>(v);
  else os << v;
  return os.str();
}

Result<Params> bind_params(const SpecString& spec, std::span<const ParamSpec> table) {
  Params p;
  for (const auto& [key, value] : spec.values) {
    const ParamSpec* ps = nullptr;
    for (const auto& t : table) if (t.name == key) ps = &t;
    if (!ps) {
      std::string known;
      for (const auto& t : table) known += (known.empty() ? "" : ", ") + t.name;
      return invalid_argument("codec '" + spec.codec + "': unknown parameter '" + key + "' (known: " + known + ")");
    }
    std::string v = value;
    if (ps->type == ParamSpec::Type::choice) {
      bool found = false;
      for (const auto& c : ps->choices) found |= (c == v);
      if (!found) {
        std::string cs;
        for (const auto& c : ps->choices) cs += (cs.empty() ? "" : "|") + c;
        return invalid_argument("codec '" + spec.codec + "': " + key + "=" + v + " is not one of " + cs);
      }
    } else {
      bool integer = ps->type == ParamSpec::Type::integer;
      double d = 0;
      if (!parse_number(v, integer, d))
        return invalid_argument("codec '" + spec.codec + "': " + key + "=" + v + " is not " +
                                (integer ? "an integer" : "a number"));
      if (d < ps->min || d > ps->max)
        return invalid_argument("codec '" + spec.codec + "': " + key + "=" + v + " is outside [" +
                                format_number(ps->min, integer) + ", " + format_number(ps->max, integer) + "]");
      v = format_number(d, integer);
    }
    p.m_values[key] = v;
    p.m_set[key] = true;
  }
  std::string canon = spec.codec;
  for (const auto& t : table) {
    if (!p.m_values.count(t.name)) p.m_values[t.name] = t.default_value;
    canon += ":" + t.name + "=" + p.m_values[t.name];
  }
  p.m_canonical = canon;
  return p;
}

const std::string& Params::get(const std::string& name) const {
  static const std::string k_empty;
  auto it = m_values.find(name);
  return it == m_values.end() ? k_empty : it->second;
}
long long Params::get_int(const std::string& name) const { return std::strtoll(get(name).c_str(), nullptr, 10); }
double Params::get_real(const std::string& name) const { return std::strtod(get(name).c_str(), nullptr); }

std::string describe_params(std::span<const ParamSpec> table) {
  std::ostringstream os;
  for (const auto& t : table) {
    os << "  " << t.name << "  ";
    switch (t.type) {
      case ParamSpec::Type::integer: os << "int [" << format_number(t.min, true) << ", " << format_number(t.max, true) << "]"; break;
      case ParamSpec::Type::real: os << "real [" << t.min << ", " << t.max << "]"; break;
      case ParamSpec::Type::choice: {
        std::string cs;
        for (const auto& c : t.choices) cs += (cs.empty() ? "" : "|") + c;
        os << cs;
      }
    }
    os << "  default " << t.default_value << "  -- " << t.help << (t.quality_knob ? " [quality knob]" : "") << "\n";
  }
  return os.str();
}

Result<Params> with_value(const Params& p, const std::string& key, const std::string& value, std::span<const ParamSpec> table) {
  BTFC_ASSIGN_OR_RETURN(SpecString spec, parse_spec_string(p.canonical()));
  bool placed = false;
  for (auto& [k, v] : spec.values)
    if (k == key) v = value, placed = true;
  if (!placed) spec.values.emplace_back(key, value);
  std::string text = spec.codec;
  for (const auto& [k, v] : spec.values) text += ":" + k + "=" + v;
  BTFC_ASSIGN_OR_RETURN(SpecString again, parse_spec_string(text));
  return bind_params(again, table);
}

std::string real_string(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.6g", v);
  return buf;
}

}  // namespace btfc
