#include "codecs/target.h"

#include <algorithm>
#include <climits>
#include <cmath>
#include <cstdio>
#include <map>
#include <optional>

#include "core/metrics.h"
#include "core/svd.h"

namespace btfc {
namespace {

constexpr int k_real_steps = 64;

struct Search {
  const Btf& btf;
  const Codec& codec;
  SpecString base;
  const ParamSpec& knob;
  Target target;
  Context& ctx;
  std::vector<TargetProbe> probes;
  std::map<long long, TargetProbe> cache;
  std::map<long long, std::unique_ptr<Model>> models;  // only of passing probes still candidates

  long long lo_index() const { return knob.type == ParamSpec::Type::integer ? (long long)std::llround(knob.min) : 0; }
  long long hi_index() const { return knob.type == ParamSpec::Type::integer ? (long long)std::llround(knob.max) : k_real_steps; }
  double value(long long i) const {
    return knob.type == ParamSpec::Type::integer ? double(i) : knob.min + (knob.max - knob.min) * double(i) / k_real_steps;
  }
  long long index_of(double v) const {
    if (knob.type == ParamSpec::Type::integer) return std::llround(v);
    return std::llround((v - knob.min) / (knob.max - knob.min) * k_real_steps);
  }
  std::string spec_at(long long i) const {
    std::string s = base.codec;
    char buf[64];
    if (knob.type == ParamSpec::Type::integer) std::snprintf(buf, sizeof buf, "%lld", i);
    else std::snprintf(buf, sizeof buf, "%.9g", value(i));
    bool placed = false;
    for (const auto& [k, v] : base.values) {
      if (k == knob.name) s += ":" + k + "=" + buf, placed = true;
      else s += ":" + k + "=" + v;
    }
    if (!placed) s += ":" + knob.name + "=" + buf;
    return s;
  }

  Result<TargetProbe> probe(long long i) {
    if (auto it = cache.find(i); it != cache.end()) return it->second;
    const std::string spec = spec_at(i);
    BTFC_ASSIGN_OR_RETURN(auto resolved, resolve_spec(spec));
    BTFC_ASSIGN_OR_RETURN(std::unique_ptr<Model> model, codec.encode(btf, resolved.second, ctx));
    TargetProbe p;
    p.knob = value(i);
    if (target.kind == Target::Kind::max_bytes) {
      // The .btfc file's bytes, what the user's budget is checked against: the payload plus the
      // container's headers, directions and statistics (2-3 KB on UBO2003-layout data).
      BTFC_ASSIGN_OR_RETURN(const uint64_t file_bytes, model_file_bytes(*model, codec));
      p.measure = double(file_bytes);
      p.meets = p.measure <= target.value;
    } else {
      Btf decoded;
      BTFC_RETURN_IF_ERROR(model->decode_all(decoded));
      BTFC_ASSIGN_OR_RETURN(Metrics m, compare_btf(btf, decoded, target.kind == Target::Kind::ssim));
      p.measure = target.kind == Target::Kind::psnr ? m.psnr : m.mean_ssim;
      p.meets = p.measure >= target.value;
    }
    if (p.meets) models[i] = std::move(model);
    cache[i] = p;
    probes.push_back(p);
    return p;
  }
};

const char* kind_name(Target::Kind k) {
  return k == Target::Kind::psnr ? "PSNR" : k == Target::Kind::ssim ? "mean SSIM" : ".btfc file bytes";
}

}  // namespace

const ParamSpec* quality_knob(const Codec& codec) {
  for (const ParamSpec& p : codec.params())
    if (p.quality_knob) return &p;
  return nullptr;
}

namespace {

// The knob search for one spec (the contract in target.h).
Result<TargetChoice> search_knob(const Btf& btf, const std::string& spec, const Target& target, Context& ctx) {
  BTFC_ASSIGN_OR_RETURN(auto resolved, resolve_spec(spec));  // validates the rest of the spec
  const Codec& codec = *resolved.first;
  const ParamSpec* knob = quality_knob(codec);
  if (!knob) return unsupported(std::string("codec '") + codec.name() + "' declares no quality knob to search");
  BTFC_ASSIGN_OR_RETURN(SpecString base, parse_spec_string(spec));
  Search s{btf, codec, std::move(base), *knob, target, ctx, {}, {}, {}};
  const long long lo_end = s.lo_index();
  long long hi_end = s.hi_index();
  long long start = std::clamp(s.index_of(resolved.second.get_real(knob->name)), lo_end, hi_end);
  // A byte budget probes no knob above the codec's limit for this data (or the spec's own value).
  const long long limit = target.kind == Target::Kind::max_bytes && knob->type == ParamSpec::Type::integer
                              ? codec.budget_knob_limit(btf.desc()) : 0;
  if (limit > 0) hi_end = std::clamp(limit, start, hi_end);

  // g(i) = "meets" for accuracy targets and "exceeds" for a byte budget: false then true as the
  // knob grows. Invariant: !g(lo), g(hi); lo = lo_end - 1 and hi = hi_end + 1 stand in for ends
  // never probed. Accuracy targets choose hi (cheapest that meets), a budget lo (largest that fits).
  const bool quality = target.kind != Target::Kind::max_bytes;
  auto g = [&](const TargetProbe& q) { return q.meets == quality; };
  long long lo = lo_end - 1, hi = hi_end + 1;
  BTFC_ASSIGN_OR_RETURN(TargetProbe p, s.probe(start));
  if (!quality && p.measure > 0 && knob->type == ParamSpec::Type::integer) {
    // Bytes grow about linearly with the knob: probe the estimate of the budget first, so the
    // bracketing below starts next to it (each probe is an encode).
    const long long est = std::clamp((long long)std::floor(double(start) * target.value / p.measure), lo_end, hi_end);
    if (!g(p) && est > start + 1) {
      BTFC_ASSIGN_OR_RETURN(TargetProbe q, s.probe(est));
      if (g(q)) lo = start, hi = est;
      else start = est, p = q;
    } else if (g(p) && est < start) {
      BTFC_ASSIGN_OR_RETURN(TargetProbe q, s.probe(est));
      if (g(q)) start = est, p = q;
      else lo = est, hi = start;
    }
  }
  if (hi <= hi_end) {
    // bracketed by the estimate
  } else if (g(p)) {
    hi = start;
  } else {
    lo = start;
    double last = p.measure;
    while (lo < hi_end) {  // grow geometrically until bracketed
      const long long i = std::min(hi_end, std::max(lo + 1, lo * 2));
      BTFC_ASSIGN_OR_RETURN(p, s.probe(i));
      if (g(p)) {
        hi = i;
        break;
      }
      lo = i;
      if (p.measure == last) {  // the codec clamps the knob to what the data allows: no change above
        if (!quality) hi = lo + 1;
        break;
      }
      last = p.measure;
    }
  }
  // Narrow the bracket. For a byte budget the bytes grow about linearly with the knob, so the
  // next probe is interpolated between the bracket's measures; when that one fits, its neighbour
  // (knob + 1) is tried next, which on linear bytes ends the search: two or three probes instead
  // of log2 of the range (each probe is a whole encode). An interpolated probe that did not halve
  // the bracket makes the next one a bisection, so the search never takes more than about twice
  // bisection's probes. Accuracy targets bisect.
  enum class Step { interpolate, neighbour, bisect } step = quality ? Step::bisect : Step::interpolate;
  while (hi - lo > 1 && hi <= hi_end) {
    long long mid = lo + (hi - lo) / 2;
    const auto lo_p = s.cache.find(lo), hi_p = s.cache.find(hi);
    if (step == Step::neighbour) {
      mid = lo + 1;
    } else if (step == Step::interpolate && lo_p != s.cache.end() && hi_p != s.cache.end() &&
               hi_p->second.measure > lo_p->second.measure) {
      const double f = (target.value - lo_p->second.measure) / (hi_p->second.measure - lo_p->second.measure);
      mid = std::clamp(lo + (long long)std::floor(f * double(hi - lo)), lo + 1, hi - 1);
    } else if (step == Step::interpolate) {
      step = Step::bisect;
    }
    const long long width = hi - lo;
    BTFC_ASSIGN_OR_RETURN(p, s.probe(mid));
    (g(p) ? hi : lo) = mid;
    if (quality) continue;
    if (step == Step::interpolate) step = lo == mid ? Step::neighbour : 2 * (hi - lo) > width ? Step::bisect : Step::interpolate;
    else step = Step::interpolate;
  }
  const long long chosen = quality ? hi : lo;
  if (chosen < lo_end || chosen > hi_end || !s.models.count(chosen)) {
    double best = quality ? -INFINITY : INFINITY;
    for (const TargetProbe& q : s.probes) best = quality ? std::max(best, q.measure) : std::min(best, q.measure);
    char buf[320];
    std::snprintf(buf, sizeof buf, "%s: target %s %.6g is out of reach: the best probed setting gives %.6g", spec.c_str(),
                  kind_name(target.kind), target.value, best);
    return invalid_argument(buf);
  }
  TargetChoice c;
  c.knob = knob->name;
  c.knob_value = s.value(chosen);
  c.measure = s.cache.at(chosen).measure;
  c.model = std::move(s.models.at(chosen));
  c.spec = c.model->spec();
  c.probes = std::move(s.probes);
  if (limit > 0) c.knob_limit = s.value(hi_end);
  return c;
}

// spec with the fragment's keys set, unless the spec sets them itself ("" when it does).
std::string apply_variant(const SpecString& base, const std::string& fragment) {
  auto frag = parse_spec_string(base.codec + ":" + fragment);
  if (!frag.ok()) return "";
  std::string out = base.codec;
  for (const auto& [k, v] : base.values) out += ":" + k + "=" + v;
  for (const auto& [k, v] : frag.value().values) {
    for (const auto& [bk, bv] : base.values)
      if (bk == k) return bv == v ? out : "";
    out += ":" + k + "=" + v;
  }
  return out;
}

}  // namespace

Result<TargetChoice> choose_for_target(const Btf& btf, const std::string& spec, const Target& target, Context& ctx) {
  if (!std::isfinite(target.value) || (target.kind == Target::Kind::ssim && (target.value <= 0 || target.value > 1)) ||
      (target.kind == Target::Kind::max_bytes && target.value < 1))
    return invalid_argument("target " + std::string(kind_name(target.kind)) + " " + std::to_string(target.value) + " is out of range");
  BTFC_ASSIGN_OR_RETURN(auto resolved, resolve_spec(spec));
  // Every probe factorizes the same data: an exact SVD is computed once and truncated per probe.
  const ExactSvdReuse reuse;
  if (const char* why = resolved.first->no_budget_search(); why && target.kind == Target::Kind::max_bytes)
    return unsupported(std::string(resolved.first->name()) + ": --max-bytes is not supported: " + why);
  if (target.kind != Target::Kind::max_bytes) {
    // A quality target: the knob, then each escalation setting until one reaches it; the error of
    // the last one tried (its best probe is the highest quality the codec was asked for).
    auto c = search_knob(btf, spec, target, ctx);
    if (c.ok()) return c;
    BTFC_ASSIGN_OR_RETURN(SpecString base, parse_spec_string(spec));
    for (const std::string& v : resolved.first->quality_variants()) {
      const std::string s = apply_variant(base, v);
      if (s.empty() || s == spec) continue;
      auto e = search_knob(btf, s, target, ctx);
      if (e.ok()) {
        e->variants = " the knob alone missed it; reached with " + v;
        return e;
      }
      c = std::move(e);
    }
    return c;
  }
  // A byte budget: where the knob counts components of a randomized SVD (fmf's rank), the probes
  // take the leading components of a few larger factorizations (core/svd.h).
  const RandomizedSvdReuse randomized(int(std::min<long long>(INT_MAX, resolved.first->budget_knob_limit(btf.desc()))));
  const std::vector<std::string> variants = resolved.first->budget_variants(resolved.second);
  if (variants.empty()) return search_knob(btf, spec, target, ctx);
  // A byte budget over the codec's settings: the knob per setting, then the best PSNR.
  BTFC_ASSIGN_OR_RETURN(SpecString base, parse_spec_string(spec));
  std::vector<std::string> specs;
  for (const std::string& v : variants) {
    const std::string s = apply_variant(base, v);
    if (!s.empty() && std::find(specs.begin(), specs.end(), s) == specs.end()) specs.push_back(s);
  }
  if (specs.empty()) return search_knob(btf, spec, target, ctx);
  std::optional<TargetChoice> best;
  Status last;
  std::vector<TargetProbe> probes;
  std::string tried;
  for (const std::string& s : specs) {
    auto c = search_knob(btf, s, target, ctx);
    if (!c.ok()) {
      last = c.status();
      continue;
    }
    Btf decoded;
    BTFC_RETURN_IF_ERROR(c->model->decode_all(decoded));
    BTFC_ASSIGN_OR_RETURN(Metrics m, compare_btf(btf, decoded, false));
    for (const TargetProbe& p : c->probes) probes.push_back(p);
    char buf[64];
    std::snprintf(buf, sizeof buf, " %.3f dB;", m.psnr);
    tried += " " + c->spec + ":" + buf;
    c->psnr = m.psnr;
    // At the knob's limit, the later settings (fewer bits at no larger knob) cannot be more accurate.
    const bool at_limit = c->knob_limit > 0 && c->knob_value >= c->knob_limit;
    if (!best || m.psnr > best->psnr) best = std::move(c).value();
    if (at_limit && &s != &specs.back()) {
      tried += " (the rest skipped: this one fits at the knob's limit)";
      break;
    }
  }
  if (!best) return last;
  best->probes = std::move(probes);
  best->variants = tried;
  return std::move(*best);
}

}  // namespace btfc
