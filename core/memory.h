// Memory limits for bounded-memory (out-of-core) work: `--max-memory SIZE` parsing, the default
// limit, and the process's peak resident memory.
#pragma once
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>

#include "core/status.h"
#include "core/sysinfo.h"  // peak_rss_bytes

namespace btfc {

// "1G", "512M", "4GB", "1048576" (bytes), "64K", "1T"; binary units (1G = 2^30 bytes); the
// syntax of core/limits.h parse_byte_size. Zero, negative, fractional and unknown suffixes are
// invalid_argument naming `what`.
Result<size_t> parse_size(const std::string& text, const std::string& what = "--max-memory");

// The default limit: 80 % of MemAvailable in /proc/meminfo (the rest is left to the page cache
// and other processes); 4 GiB when /proc/meminfo cannot be read.
size_t default_max_memory();
// MemAvailable in /proc/meminfo in bytes (free RAM plus reclaimable page cache), 0 when unknown.
uint64_t mem_available_bytes();


// "1.50 GiB", "512.0 MiB" for messages.
std::string format_bytes(uint64_t bytes);

// Scratch memory for large temporaries (the SVD's basis, its products' staging copies): 2 MiB
// aligned with transparent huge pages requested (madvise; a hint). Fresh 4 KiB pages cost 2-3 ms
// per MB to fault on the VMs measured, huge pages 0.05-1 ms (docs/benchmarks.md, fmf section),
// which for the 10-50 MB a pass allocates is a sizeable part of the pass. Below 2 MiB plain
// malloc (a huge page would be zeroed whole for a few KB). Not zeroed; throws
// std::bad_alloc like a vector. Btf data has its own (FloatBuffer, core/btf.h, zeroed in parallel).
void* page_alloc(size_t bytes);
// Every page of p[0, bytes) touched (written) by the OpenMP threads, each its share: the kernel
// zeroes a fresh page on its first write, in the writing thread, so a buffer that the main
// thread would fill first (the SVD's basis, the products' staging) faults on all cores instead
// of one. Serial inside a parallel region. The contents stay unspecified. Only what will be
// used: a touched page is resident whether it is used or not.
void page_touch(void* p, size_t bytes);
// page_alloc, then page_touch of all of it.
void* page_alloc_touched(size_t bytes);
struct PageFree {
  void operator()(void* p) const;
};
template <class T>
class PageBuffer {
 public:
  explicit PageBuffer(size_t count) : m_p(static_cast<T*>(page_alloc(count * sizeof(T)))) {}
  T* data() { return m_p.get(); }

 private:
  std::unique_ptr<T, PageFree> m_p;
};

}  // namespace btfc
