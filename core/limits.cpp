#include "core/limits.h"

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>

namespace btfc {

namespace {

std::atomic<size_t> g_limit{0};  // 0 = not set yet

// cgroup v2's memory.max of this process ("max" or a byte count); 0 when there is none.
size_t cgroup_memory_max() {
  std::ifstream cg("/proc/self/cgroup");
  std::string line, rel;
  while (std::getline(cg, line))
    if (line.rfind("0::", 0) == 0) rel = line.substr(3);
  if (rel.empty()) return 0;
  std::ifstream f("/sys/fs/cgroup" + (rel == "/" ? std::string() : rel) + "/memory.max");
  std::string v;
  if (!(f >> v) || v.empty() || !std::isdigit(static_cast<unsigned char>(v[0]))) return 0;
  auto r = parse_byte_size(v);
  return r.ok() ? r.value() : 0;
}

size_t env_limit() {
  const char* e = std::getenv("BTFC_MAX_MEMORY");
  if (!e || !*e) return default_memory_limit();
  Result<size_t> r = parse_byte_size(e);
  if (!r.ok() || r.value() == 0) {
    std::fprintf(stderr, "btfc: warning: ignoring BTFC_MAX_MEMORY='%s' (%s)\n", e,
                 r.ok() ? "zero" : r.status().message().c_str());
    return default_memory_limit();
  }
  return r.value();
}

}  // namespace

size_t default_memory_limit() {
  size_t lim = k_max_default_memory_limit;
  const long pages = sysconf(_SC_PHYS_PAGES), page = sysconf(_SC_PAGE_SIZE);
  if (pages > 0 && page > 0 && size_t(pages) <= lim / size_t(page)) lim = size_t(pages) * size_t(page);
  if (const size_t cg = cgroup_memory_max(); cg > 0) lim = std::min(lim, cg);
  return lim;
}

size_t memory_limit() {
  size_t v = g_limit.load(std::memory_order_relaxed);
  if (v == 0) {
    v = env_limit();
    g_limit.store(v, std::memory_order_relaxed);
  }
  return v;
}

void set_memory_limit(size_t bytes) { g_limit.store(bytes == 0 ? env_limit() : bytes, std::memory_order_relaxed); }

Result<size_t> parse_byte_size(const std::string& text) {
  auto bad = [&](const char* why) { return invalid_argument("memory size '" + text + "': " + why); };
  size_t i = 0, v = 0;
  if (text.empty() || !std::isdigit(static_cast<unsigned char>(text[0]))) return bad("expected a number of bytes, e.g. 512M or 4G");
  for (; i < text.size() && std::isdigit(static_cast<unsigned char>(text[i])); ++i)
    if (__builtin_mul_overflow(v, size_t(10), &v) || __builtin_add_overflow(v, size_t(text[i] - '0'), &v)) return bad("too large");
  unsigned shift = 0;
  if (i < text.size()) {
    switch (std::toupper(static_cast<unsigned char>(text[i]))) {
      case 'K': shift = 10; break;
      case 'M': shift = 20; break;
      case 'G': shift = 30; break;
      case 'T': shift = 40; break;
      default: return bad("unknown suffix (use K, M, G or T)");
    }
    ++i;
    if (i < text.size() && (text[i] == 'B' || text[i] == 'b')) ++i;  // "4GB" reads as 4 GiB too
    if (i != text.size()) return bad("trailing characters");
  }
  if (shift && v > (~size_t(0) >> shift)) return bad("too large");
  return v << shift;
}

Status check_memory(size_t bytes, const std::string& what) {
  const size_t lim = memory_limit();
  if (bytes <= lim) return {};
  return invalid_argument(what + " needs " + std::to_string(bytes) + " bytes (" + std::to_string(bytes >> 20) +
                          " MiB), over the memory limit of " + std::to_string(lim) +
                          " bytes (raise it with --max-memory or BTFC_MAX_MEMORY)");
}

}  // namespace btfc
