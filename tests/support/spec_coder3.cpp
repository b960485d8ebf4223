// Entropy coder 3 (spec §7.2.2) read literally, for the tests that check
// the library's coder 3 payloads against the spec rather than against the
// library's own decoder (test_entropy_lanes, test_predicted_codec).
#include "spec_coder3.hpp"

#include <gtest/gtest.h>

#include <algorithm>

namespace ivol::test {

std::vector<std::uint16_t> spec_coder3_decode(const std::uint8_t* b, std::size_t size, const BrickDims& d) {
  const std::size_t n = std::size_t{d[0]} * d[1] * d[2];
  std::vector<std::uint16_t> z(n);
  Bits tables{b, size};
  std::uint32_t f[12][32] = {}, s[12][32] = {};
  for (int k = 0; k < 12; ++k) {
    if (tables.get(1) == 0) {
      for (int t = 0; t < 32; ++t) f[k][t] = 128;
    } else {
      const std::uint32_t present = tables.get(32);
      if (present == 0) return ADD_FAILURE() << "present = 0", z;
      int last = 31;
      while (!(present >> last & 1)) --last;
      std::uint32_t sum = 0;
      for (int t = 0; t < last; ++t) {
        if (!(present >> t & 1)) continue;
        const std::uint32_t a = tables.get(4);
        if (a > 11) return ADD_FAILURE() << "a = " << a, z;
        f[k][t] = (1u << a) + tables.get(a);
        sum += f[k][t];
      }
      if (sum >= 4096) return ADD_FAILURE() << "sum " << sum, z;
      f[k][last] = 4096 - sum;
    }
    for (int t = 1; t < 32; ++t) s[k][t] = s[k][t - 1] + f[k][t - 1];
  }
  if (!tables.ok) return ADD_FAILURE() << "tables cut", z;
  const std::size_t at = (tables.at + 7) / 8;
  if (tables.at % 8 && (b[at - 1] >> (tables.at % 8)) != 0) return ADD_FAILURE() << "table padding", z;
  if (size < at + 132) return ADD_FAILURE() << "no states", z;
  std::uint64_t X[32];
  for (int l = 0; l < 32; ++l) {
    X[l] = le32(b + at + 4 * l);
    if (X[l] < 65536) return ADD_FAILURE() << "state " << l, z;
  }
  const std::uint64_t W = le32(b + at + 128);
  const std::uint8_t* words = b + at + 132;
  if (2 * W > size - at - 132) return ADD_FAILURE() << "W", z;
  std::uint64_t next = 0;
  std::vector<unsigned> tokens(n), lengths(n);
  auto length_at = [&](long x, long y, long zz) -> unsigned {
    if (x < 0 || y < 0 || zz < 0 || x >= long(d[0]) || y >= long(d[1]) || zz >= long(d[2])) return 0;
    return lengths[(std::size_t(zz) * d[1] + std::size_t(y)) * d[0] + std::size_t(x)];
  };
  std::size_t i = 0;
  for (long zz = 0; zz < long(d[2]); ++zz)
    for (long y = 0; y < long(d[1]); ++y)
      for (long x = 0; x < long(d[0]); ++x, ++i) {
        const unsigned sum = 2 * length_at(x, y - 1, zz) + length_at(x, y, zz - 1) + length_at(x - 1, y - 1, zz) +
                             length_at(x + 1, y - 1, zz) + 2;
        const unsigned k = std::min(11u, sum / 5);
        std::uint64_t& x_state = X[i % 32];
        const std::uint64_t slot = x_state % 4096;
        unsigned t = 0;
        while (!(s[k][t] <= slot && slot < s[k][t] + f[k][t])) ++t;
        x_state = f[k][t] * (x_state / 4096) + slot - s[k][t];
        if (x_state < 65536) {
          if (next == W) return ADD_FAILURE() << "words end", z;
          x_state = 65536 * x_state + (words[2 * next] | words[2 * next + 1] << 8);
          ++next;
        }
        tokens[i] = t, lengths[i] = token_length(t);
      }
  for (std::uint64_t x : X)
    if (x != 65536) return ADD_FAILURE() << "state end " << x, z;
  if (next != W) return ADD_FAILURE() << "words left", z;
  Bits below{words + 2 * W, size - at - 132 - 2 * W};
  for (std::size_t v = 0; v < n; ++v) {
    const unsigned t = tokens[v], e = t < 4 ? 0 : token_length(t) - 2;
    z[v] = static_cast<std::uint16_t>(t < 2 ? t : ((2u + (t & 1)) << e) + below.get(e));
  }
  if (!below.ok) return ADD_FAILURE() << "bits cut", z;
  if ((below.at + 7) / 8 != below.size) return ADD_FAILURE() << "bits size", z;
  if (below.at % 8 && (below.data[below.size - 1] >> (below.at % 8)) != 0) return ADD_FAILURE() << "padding", z;
  return z;
}

}  // namespace ivol::test
