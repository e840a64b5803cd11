// Shared helpers of the libFuzzer targets (tests/fuzz/*.cpp, docs/robustness.md).
//
// btfc's readers take a path (they seek, stat and stream multi-GB files), so each input is
// written to an anonymous in-memory file (memfd) and opened as /proc/self/fd/N: no disk I/O,
// nothing left behind, and the readers run exactly the code a user's file meets.
#pragma once
#include <sys/mman.h>
#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <cstdint>
#include <cstdlib>
#include <string>

#include "codecs/codec.h"
#include "core/limits.h"

namespace btfc::fuzz {

// One memfd per process, rewritten for every input.
class MemFile {
 public:
  MemFile() {
    m_fd = memfd_create("btfc-fuzz", 0);
    if (m_fd < 0) std::abort();
    m_path = "/proc/self/fd/" + std::to_string(m_fd);
  }
  const std::string& write(const uint8_t* p, size_t n) {
    if (ftruncate(m_fd, 0) != 0) std::abort();
    size_t done = 0;
    while (done < n) {
      const ssize_t k = pwrite(m_fd, p + done, n - done, off_t(done));
      if (k <= 0) std::abort();
      done += size_t(k);
    }
    return m_path;
  }

 private:
  int m_fd = -1;
  std::string m_path;
};

// Process-wide settings of every target: CPU path (PoCL under ASan is slow and leaks), one
// thread (the machine is shared), and a memory limit far above what a <= 64 KiB input may
// legitimately need, so an allocation sized by an unchecked field fails here (and libFuzzer's
// -malloc_limit_mb catches any allocation that bypasses the limit).
inline void init_process() {
  setenv("BTFC_FORCE_CPU", "1", 1);
  setenv("OMP_NUM_THREADS", "1", 1);
  set_memory_limit(size_t(64) << 20);
}

// Rewrites every CRC of a .btfc image in place (file header and each chunk whose size field
// fits), so mutations inside payloads reach the parsers behind the CRC check instead of
// stopping at it. Chunk layout: docs/FORMAT.md.
inline void repair_crcs(uint8_t* p, size_t n) {
  auto rd64 = [&](size_t o) {
    uint64_t v = 0;
    for (int i = 0; i < 8; ++i) v |= uint64_t(p[o + size_t(i)]) << (8 * i);
    return v;
  };
  auto wr32 = [&](size_t o, uint32_t v) {
    for (int i = 0; i < 4; ++i) p[o + size_t(i)] = uint8_t(v >> (8 * i));
  };
  if (n < 32) return;
  wr32(28, uint32_t(crc32(0, p, 28)));
  size_t pos = 32;
  while (n - pos >= 32) {
    const uint64_t size = rd64(pos + 8);
    if (size > n - pos - 32) break;
    uint32_t c = uint32_t(crc32(0, p + pos, 28));
    c = uint32_t(crc32(c, p + pos + 32, uInt(size)));
    wr32(pos + 28, c);
    pos += 32 + size_t(size) + size_t((16 - size % 16) % 16);
    if (pos > n) break;
  }
}

// Exercises a loaded model the way the CLI does, on a bounded piece: a corner region of at most
// 3 x 3 texels and 2 lights x 2 views, single evaluations (measured and interpolated), and the
// GPU tensors. Every call must either succeed or return an error; values are not checked (the
// golden and codec tests do that).
inline void exercise(const Model& m) {
  const BtfDesc& d = m.desc();
  DecodeRequest req;
  req.width = std::min(d.width, 3);
  req.height = std::min(d.height, 3);
  for (int i = 0; i < int(std::min<size_t>(d.num_lights(), 2)); ++i) req.lights.push_back(i);
  for (int i = 0; i < int(std::min<size_t>(d.num_views(), 2)); ++i) req.views.push_back(int(d.num_views()) - 1 - i);
  Btf out;
  (void)m.decode(req, out);
  if (d.channels > 0 && d.channels <= 64) {
    float v[64];
    m.eval(d.width - 1, d.height - 1, int(d.num_lights()) - 1, int(d.num_views()) - 1, v);
    (void)m.eval_dir(0, 0, dir_from_theta_phi(0.3, 1.0), dir_from_theta_phi(0.7, 2.0), v);
    (void)m.eval_lod(0, 0, 0, 0, 0.5, v);
  }
  (void)m.gpu_tensors();
}

}  // namespace btfc::fuzz
