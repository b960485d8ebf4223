// Entropy coder 3 (spec §7.2.2) read literally (spec_coder3.cpp).
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "ivol/predicted_codec.hpp"

namespace ivol::test {

// A little-endian u32.
inline std::uint32_t le32(const std::uint8_t* p) {
  return std::uint32_t{p[0]} | std::uint32_t{p[1]} << 8 | std::uint32_t{p[2]} << 16 | std::uint32_t{p[3]} << 24;
}

// Bits LSB first, as §7.2.2's tables and §7.2.1's bits below are packed.
struct Bits {
  const std::uint8_t* data;
  std::size_t size, at = 0;
  bool ok = true;
  std::uint32_t get(unsigned count) {
    std::uint32_t v = 0;
    for (unsigned k = 0; k < count; ++k, ++at) {
      if (at / 8 >= size) return ok = false, 0;
      v |= std::uint32_t{(data[at / 8] >> (at % 8)) & 1u} << k;
    }
    return v;
  }
};

// A value's bit length, and the bit length of the residuals token t stands for.
inline unsigned bit_length(unsigned z) { return z ? 32 - static_cast<unsigned>(__builtin_clz(z)) : 0; }
inline unsigned token_length(unsigned t) { return t < 2 ? t : (t >> 1) + 1; }

// The residuals of a brick of `d` from its coded residuals [b, b + size)
// (a codec 3 payload after its header). Fails the running test, returning
// what it has, where a rule of §7.2.2 fails.
std::vector<std::uint16_t> spec_coder3_decode(const std::uint8_t* b, std::size_t size, const BrickDims& d);

}  // namespace ivol::test
