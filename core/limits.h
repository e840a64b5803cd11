// Process-wide resource limits (docs/robustness.md, "Memory limit").
//
// A file from elsewhere declares its own sizes; a reader must not trust them with memory. Two
// rules hold together:
//  1. Readers bound every allocation by the bytes the file actually holds (checked in the
//     container, the Bonn readers and the model loaders before allocating).
//  2. Anything whose size is declared rather than stored (a decoded BTF: width x height x
//     lights x views x channels floats, or a model's expanded tensors) is checked against the
//     memory limit *before* allocating, and fails with an error that names the size and the
//     limit.
// The limit defaults to the environment variable BTFC_MAX_MEMORY (bytes, or with a K/M/G/T
// suffix, powers of 1024) when set and valid, else to the machine's memory
// (default_memory_limit()): a decode declared bigger than all the RAM there is cannot succeed
// (it would only swap the machine to a halt or be killed by the OOM killer), so a small file
// that declares one (a "decompression bomb") is refused with an error instead. A malformed
// BTFC_MAX_MEMORY is ignored with a warning on stderr rather than turning every command into an
// error. Thread-safe (an atomic).
#pragma once
#include <cstddef>
#include <string>

#include "core/status.h"

namespace btfc {

// The overflow guard: no limit is ever above 1 TiB unless set explicitly.
constexpr size_t k_max_default_memory_limit = size_t(1) << 40;

// The default limit without BTFC_MAX_MEMORY: the physical memory (sysconf), lowered to the
// cgroup's memory.max when the process runs in a container that sets one; at most
// k_max_default_memory_limit, and k_max_default_memory_limit when neither can be read.
size_t default_memory_limit();

// The current limit in bytes (reads BTFC_MAX_MEMORY on first use).
size_t memory_limit();
// Overrides the limit for this process (0 restores the default / environment value).
void set_memory_limit(size_t bytes);
// "512M", "4G", "1073741824" -> bytes; errors on anything else (negative, empty, overflow,
// unknown suffix).
Result<size_t> parse_byte_size(const std::string& text);
// ok when `bytes` fit the limit, else invalid_argument "<what> needs N bytes (X MiB), over the
// memory limit of L bytes (raise it with --max-memory or BTFC_MAX_MEMORY)". The CLI's --max-memory
// (compress, decompress, bench) sets this limit when given.
Status check_memory(size_t bytes, const std::string& what);

}  // namespace btfc
