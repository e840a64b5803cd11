// The input layout of fuzz_image_set (tests/fuzz/fuzz_image_set.cpp), shared with the test that
// replays its regression files (tests/io/fuzz_regress_io_test.cpp): a flag byte, then up to 16
// entries "u8 name length, name, u16 LE data length, data" written as files into a directory.
#pragma once
#include <algorithm>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>

namespace btfc::fuzz {

// Writes the entries of `data` into the existing, empty directory `dir`. A name holds at most one
// '/' (a view folder, created as needed); names that would leave `dir` ("..", absolute, empty
// parts) or collide with a folder are skipped. Returns the flag byte (0 for an empty input).
inline uint8_t write_image_set_entries(const uint8_t* data, size_t size, const std::string& dir) {
  namespace fs = std::filesystem;
  if (size < 1) return 0;
  auto safe = [](const std::string& c) { return !c.empty() && c != "." && c != ".." && c.find('\0') == std::string::npos; };
  std::error_code ec;
  size_t pos = 1;
  for (int n = 0; n < 16 && pos < size; ++n) {
    const size_t nlen = data[pos++];
    if (nlen > size - pos) break;
    const std::string name(reinterpret_cast<const char*>(data + pos), nlen);
    pos += nlen;
    size_t dlen = 0;
    if (size - pos >= 2) {
      dlen = size_t(data[pos]) | size_t(data[pos + 1]) << 8;
      pos += 2;
    } else {
      pos = size;
    }
    dlen = std::min(dlen, size - pos);
    const uint8_t* body = data + pos;
    pos += dlen;
    const size_t slash = name.find('/');
    const std::string sub = slash == std::string::npos ? "" : name.substr(0, slash);
    const std::string file = slash == std::string::npos ? name : name.substr(slash + 1);
    if (!safe(file) || (slash != std::string::npos && !safe(sub))) continue;
    if (!sub.empty()) {
      fs::create_directory(dir + "/" + sub, ec);
      if (!fs::is_directory(dir + "/" + sub, ec)) continue;
    }
    const std::string p = dir + "/" + (sub.empty() ? file : sub + "/" + file);
    if (fs::is_directory(p, ec)) continue;
    std::ofstream(p, std::ios::binary).write(reinterpret_cast<const char*>(body), std::streamsize(dlen));
  }
  return data[0];
}

}  // namespace btfc::fuzz
