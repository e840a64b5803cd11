// Bit packing and canonical Huffman coding of codebook index streams (paper section 4.2).
//
// Hand-written rather than taken from a library: the paper's choice is per stream between the
// minimal-bit plain packing and a static Huffman code *with the code table counted*, over
// alphabets as large as a codebook (10^5 - 10^6 symbols). zlib and zstd expose no such
// large-alphabet Huffman coder (deflate's alphabets are <= 286 symbols, huf0 is internal to zstd).
// Contracts in mlvq_internal.h.
#include <algorithm>
#include <queue>

#include "codecs/mlvq/mlvq_internal.h"
#include "core/limits.h"

namespace btfc::mlvq {

namespace {

constexpr int k_max_len = 24;
constexpr int k_len_bits = 5;

class BitWriter {
 public:
  void put(uint64_t v, int n) {  // LSB-first
    for (int i = 0; i < n; ++i) {
      if ((m_bits & 7) == 0) m_bytes.push_back(0);
      if ((v >> i) & 1) m_bytes.back() |= uint8_t(1u << (m_bits & 7));
      ++m_bits;
    }
  }
  std::vector<uint8_t>& bytes() { return m_bytes; }

 private:
  std::vector<uint8_t> m_bytes;
  uint64_t m_bits = 0;
};

class BitReader {
 public:
  BitReader(std::span<const uint8_t> b) : m_b(b) {}
  bool get(int n, uint64_t& v) {
    v = 0;
    if (m_pos + uint64_t(n) > uint64_t(m_b.size()) * 8) return false;
    for (int i = 0; i < n; ++i, ++m_pos) v |= uint64_t((m_b[m_pos >> 3] >> (m_pos & 7)) & 1) << i;
    return true;
  }
  bool bit(uint32_t& v) {
    if (m_pos >= uint64_t(m_b.size()) * 8) return false;
    v = (m_b[m_pos >> 3] >> (m_pos & 7)) & 1;
    ++m_pos;
    return true;
  }

 private:
  std::span<const uint8_t> m_b;
  uint64_t m_pos = 0;
};

// Huffman code lengths of the symbols with non-zero frequency, limited to k_max_len by halving
// the frequencies (keeping them >= 1) until the tree is shallow enough.
std::vector<uint8_t> code_lengths(std::vector<uint64_t> freq) {
  const size_t n = freq.size();
  std::vector<uint8_t> len(n, 0);
  for (;;) {
    std::vector<size_t> used;
    for (size_t i = 0; i < n; ++i)
      if (freq[i]) used.push_back(i);
    if (used.size() == 1) {
      len[used[0]] = 1;
      return len;
    }
    // Nodes: leaves 0..u-1, internal nodes after; parent links give the depths.
    const size_t u = used.size();
    std::vector<size_t> parent(2 * u, 0);
    using Item = std::pair<uint64_t, size_t>;
    std::priority_queue<Item, std::vector<Item>, std::greater<Item>> pq;
    for (size_t i = 0; i < u; ++i) pq.push({freq[used[i]], i});
    size_t next = u;
    while (pq.size() > 1) {
      const Item a = pq.top();
      pq.pop();
      const Item b = pq.top();
      pq.pop();
      parent[a.second] = parent[b.second] = next;
      pq.push({a.first + b.first, next++});
    }
    const size_t root = next - 1;
    std::vector<int> depth(next, 0);
    for (size_t i = root; i-- > 0;) depth[i] = depth[parent[i]] + 1;
    int mx = 0;
    for (size_t i = 0; i < u; ++i) mx = std::max(mx, depth[i]);
    if (mx <= k_max_len) {
      for (size_t i = 0; i < u; ++i) len[used[i]] = uint8_t(depth[i]);
      return len;
    }
    for (uint64_t& f : freq)
      if (f) f = std::max<uint64_t>(1, f / 2);
  }
}

// Canonical codes: symbols sorted by (length, symbol), consecutive code values per length.
std::vector<uint32_t> canonical_codes(const std::vector<uint8_t>& len) {
  uint32_t count[k_max_len + 2] = {0}, next[k_max_len + 2] = {0};
  for (uint8_t l : len) count[l]++;
  count[0] = 0;
  uint32_t code = 0;
  for (int l = 1; l <= k_max_len; ++l) code = (code + count[l - 1]) << 1, next[l] = code;
  std::vector<uint32_t> codes(len.size(), 0);
  for (size_t s = 0; s < len.size(); ++s)
    if (len[s]) codes[s] = next[len[s]]++;
  return codes;
}

}  // namespace

int plain_bits(uint32_t alphabet) {
  int b = 0;
  while (b < 32 && (uint64_t(1) << b) < alphabet) ++b;
  return b;
}

CodedStream encode_indices(std::span<const uint32_t> v, uint32_t alphabet, bool allow_huffman) {
  CodedStream out;
  const int w = plain_bits(alphabet);
  BitWriter plain;
  for (uint32_t x : v) plain.put(x, w);
  out.plain_bytes = 1 + plain.bytes().size();
  out.bytes.push_back(0);
  out.bytes.insert(out.bytes.end(), plain.bytes().begin(), plain.bytes().end());
  out.huffman_bytes = out.plain_bytes;
  if (!allow_huffman || v.empty() || alphabet > (1u << 26)) return out;
  std::vector<uint64_t> freq(alphabet, 0);
  for (uint32_t x : v) freq[x]++;
  const std::vector<uint8_t> len = code_lengths(freq);
  const std::vector<uint32_t> codes = canonical_codes(len);
  BitWriter hw;
  for (uint32_t s = 0; s < alphabet; ++s) hw.put(len[s], k_len_bits);
  for (uint32_t x : v)
    for (int i = len[x] - 1; i >= 0; --i) hw.put((codes[x] >> i) & 1, 1);
  out.huffman_bytes = 1 + hw.bytes().size();
  if (out.huffman_bytes < out.plain_bytes) {
    out.huffman = true;
    out.bytes.assign(1, 1);
    out.bytes.insert(out.bytes.end(), hw.bytes().begin(), hw.bytes().end());
  }
  return out;
}

Result<std::vector<uint32_t>> decode_indices(std::span<const uint8_t> bytes, size_t count, uint32_t alphabet, const std::string& what) {
  auto bad = [&](const std::string& m) { return corrupt_data(what + ": " + m); };
  if (bytes.empty()) return bad("empty index stream");
  if (alphabet == 0) return bad("index stream into an empty codebook");
  // Nothing is sized by `count` (up to 2^28 x 64 from a model file) before the stream is known to
  // hold that many indices: plain ones take exactly w bits each, Huffman codes at least 1 bit.
  if (uint64_t(count) > (uint64_t(1) << 40)) return bad(std::to_string(count) + " indices declared");
  BitReader br(bytes.subspan(1));
  if (bytes[0] == 0) {
    const int w = plain_bits(alphabet);
    if ((uint64_t(count) * uint64_t(w) + 7) / 8 != bytes.size() - 1) return bad("plain index stream has " + std::to_string(bytes.size() - 1) + " bytes, expected " + std::to_string((uint64_t(count) * uint64_t(w) + 7) / 8));
    // A 1-entry codebook stores 0 bits per index, so only the memory limit bounds the count.
    if (w == 0) BTFC_RETURN_IF_ERROR(check_memory(count * sizeof(uint32_t), what + ": " + std::to_string(count) + " indices"));
    std::vector<uint32_t> v(count);
    for (size_t i = 0; i < count; ++i) {
      uint64_t x;
      if (!br.get(w, x)) return bad("truncated plain index stream");
      if (x >= alphabet) return bad("index " + std::to_string(x) + " >= codebook size " + std::to_string(alphabet));
      v[i] = uint32_t(x);
    }
    return v;
  }
  if (bytes[0] != 1) return bad("unknown index coding " + std::to_string(bytes[0]));
  if (alphabet > (1u << 26)) return bad("Huffman alphabet too large");
  if (uint64_t(alphabet) * k_len_bits > (uint64_t(bytes.size()) - 1) * 8) return bad("truncated Huffman code table");
  std::vector<uint8_t> len(alphabet);
  uint32_t count_len[k_max_len + 1] = {0};
  for (uint32_t s = 0; s < alphabet; ++s) {
    uint64_t l;
    (void)br.get(k_len_bits, l);
    if (l > k_max_len) return bad("Huffman code length " + std::to_string(l) + " > " + std::to_string(k_max_len));
    len[s] = uint8_t(l);
    count_len[l]++;
  }
  // Kraft check: a complete or under-full prefix code (a single symbol has length 1).
  uint64_t kraft = 0;
  for (int l = 1; l <= k_max_len; ++l) kraft += uint64_t(count_len[l]) << (k_max_len - l);
  if (kraft == 0 || kraft > (uint64_t(1) << k_max_len)) return bad("invalid Huffman code table");
  const uint64_t code_bits = (uint64_t(bytes.size()) - 1) * 8 - uint64_t(alphabet) * k_len_bits;
  if (uint64_t(count) > code_bits)
    return bad("truncated Huffman index stream: " + std::to_string(count) + " indices in " + std::to_string(code_bits) + " bits of codes");
  std::vector<uint32_t> v(count);
  // Canonical decoding tables: per length the first code, its count and the symbol offset.
  std::vector<uint32_t> sorted;
  sorted.reserve(alphabet);
  for (int l = 1; l <= k_max_len; ++l)
    for (uint32_t s = 0; s < alphabet; ++s)
      if (len[s] == l) sorted.push_back(s);
  uint32_t first[k_max_len + 2] = {0}, offset[k_max_len + 2] = {0};
  uint32_t code = 0, off = 0;
  for (int l = 1; l <= k_max_len; ++l) {
    code = (code + (l > 1 ? count_len[l - 1] : 0)) << 1;
    if (l == 1) code = 0;
    first[l] = code, offset[l] = off;
    off += count_len[l];
  }
  for (size_t i = 0; i < count; ++i) {
    uint32_t c = 0;
    int l = 0;
    for (;;) {
      uint32_t b;
      if (!br.bit(b)) return bad("truncated Huffman index stream");
      c = (c << 1) | b;
      ++l;
      if (l > k_max_len) return bad("undecodable Huffman code");
      if (count_len[l] && c >= first[l] && c - first[l] < count_len[l]) {
        v[i] = sorted[offset[l] + (c - first[l])];
        break;
      }
    }
  }
  return v;
}

}  // namespace btfc::mlvq
