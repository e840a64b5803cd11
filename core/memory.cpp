#include "core/memory.h"

#include <sys/resource.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>

namespace btfc {

Result<size_t> parse_size(const std::string& text, const std::string& what) {
  const char* s = text.c_str();
  char* end = nullptr;
  const double v = std::strtod(s, &end);
  if (end == s || !std::isfinite(v) || v <= 0)
    return invalid_argument(what + ": '" + text + "' is not a positive size (e.g. 512M, 2G)");
  double mult = 1;
  std::string suffix(end);
  if (suffix == "b" || suffix == "B") suffix.clear();
  if (suffix.size() == 2 && (suffix[1] == 'B' || suffix[1] == 'b')) suffix.pop_back();  // "GB" = "G"
  if (suffix.size() == 3 && suffix.substr(1) == "iB") suffix.resize(1);                 // "GiB" = "G"
  if (!suffix.empty()) {
    if (suffix.size() != 1) return invalid_argument(what + ": unknown size suffix in '" + text + "' (use K, M, G or T)");
    switch (suffix[0]) {
      case 'k': case 'K': mult = 1024.0; break;
      case 'm': case 'M': mult = 1024.0 * 1024; break;
      case 'g': case 'G': mult = 1024.0 * 1024 * 1024; break;
      case 't': case 'T': mult = 1024.0 * 1024 * 1024 * 1024; break;
      default: return invalid_argument(what + ": unknown size suffix in '" + text + "' (use K, M, G or T)");
    }
  }
  const double bytes = v * mult;
  if (bytes < 1 || bytes > 1e18) return invalid_argument(what + ": '" + text + "' is out of range");
  return size_t(bytes);
}

size_t default_max_memory() {
  std::ifstream f("/proc/meminfo");
  std::string line;
  while (std::getline(f, line)) {
    std::istringstream ss(line);
    std::string key;
    unsigned long long kb = 0;
    if (ss >> key >> kb && key == "MemAvailable:" && kb > 0) return size_t(double(kb) * 1024 * 0.8);
  }
  return size_t(4) << 30;
}

uint64_t peak_rss_bytes() {
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  return uint64_t(ru.ru_maxrss) * 1024;  // Linux reports KiB
}

std::string format_bytes(uint64_t b) {
  char buf[64];
  if (b >= (uint64_t(1) << 30)) std::snprintf(buf, sizeof buf, "%.2f GiB", double(b) / double(uint64_t(1) << 30));
  else std::snprintf(buf, sizeof buf, "%.1f MiB", double(b) / double(1 << 20));
  return buf;
}

}  // namespace btfc
