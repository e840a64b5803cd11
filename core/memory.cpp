#include "core/memory.h"

#include "core/limits.h"

#include <sys/mman.h>
#include <sys/resource.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <new>
#include <sstream>

namespace btfc {

Result<size_t> parse_size(const std::string& text, const std::string& what) {
  // One size syntax for the CLI and BTFC_MAX_MEMORY (core/limits.h).
  auto r = parse_byte_size(text);
  if (!r.ok()) return invalid_argument(what + ": " + r.status().message());
  if (r.value() == 0) return invalid_argument(what + ": '" + text + "' is not a positive size (e.g. 512M, 2G)");
  return r;
}

void* page_alloc(size_t bytes) {
  const size_t k_align = size_t(2) << 20;
  if (bytes < k_align) {  // small: a huge page would be zeroed whole for a few KB
    void* p = std::malloc(std::max<size_t>(1, bytes));
    if (!p) throw std::bad_alloc();
    return p;
  }
  const size_t size = (bytes + k_align - 1) / k_align * k_align;
  void* p = std::aligned_alloc(k_align, size);
  if (!p) throw std::bad_alloc();
  madvise(p, size, MADV_HUGEPAGE);  // a hint; failure only costs speed
  return p;
}

void page_touch(void* p, size_t bytes) {
  char* const c = static_cast<char*>(p);
  constexpr size_t k_page = 4096;
  const long long pages = (long long)((bytes + k_page - 1) / k_page);
#pragma omp parallel for schedule(static) if (pages >= 1024)
  for (long long i = 0; i < pages; ++i) c[size_t(i) * k_page] = 0;
}

void* page_alloc_touched(size_t bytes) {
  void* const p = page_alloc(bytes);
  page_touch(p, bytes);
  return p;
}

void PageFree::operator()(void* p) const { std::free(p); }

uint64_t mem_available_bytes() {
  std::ifstream f("/proc/meminfo");
  std::string line;
  while (std::getline(f, line)) {
    std::istringstream ss(line);
    std::string key;
    unsigned long long kb = 0;
    if (ss >> key >> kb && key == "MemAvailable:" && kb > 0) return uint64_t(kb) * 1024;
  }
  return 0;
}

size_t default_max_memory() {
  const uint64_t avail = mem_available_bytes();
  return avail ? size_t(double(avail) * 0.8) : size_t(4) << 30;
}

std::string format_bytes(uint64_t b) {
  char buf[64];
  if (b >= (uint64_t(1) << 30)) std::snprintf(buf, sizeof buf, "%.2f GiB", double(b) / double(uint64_t(1) << 30));
  else std::snprintf(buf, sizeof buf, "%.1f MiB", double(b) / double(1 << 20));
  return buf;
}

}  // namespace btfc
