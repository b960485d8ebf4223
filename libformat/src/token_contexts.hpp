// What codec 3's entropy coders 2 and 3 share (spec §7.2.1, §7.2.2): a
// residual's token and the bits below it, and the twelve contexts a voxel
// is coded in, from the tokens of earlier rows.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "ivol/predicted_codec.hpp"

namespace ivol::detail {

inline constexpr unsigned kTokenContexts = 12;
inline constexpr unsigned kTokenCount = 32;
inline constexpr unsigned kTableBits = 12;  // every table of frequencies sums to 2^12
inline constexpr std::uint32_t kTableTotal = 1u << kTableBits;

// The bit length of the residuals a token stands for.
constexpr unsigned token_bit_length(unsigned t) { return t < 2 ? t : (t >> 1) + 1; }

// How many bits follow token t in the stream of bits below: its bit length
// less 2, none for lengths 0 .. 2.
constexpr unsigned bits_below_token(unsigned t) { return t < 4 ? 0 : (t >> 1) - 1; }

// The tokens of n residuals and their bit lengths.
void tokens_of(const std::uint16_t* z, std::size_t n, std::uint8_t* tokens, std::uint8_t* lengths);

// The contexts of a row of voxels from the bit lengths of the tokens in the
// row before it along y (`up`) and along z (`back`), 0 outside the brick.
// `padded` holds nx + 2 bytes, 0 at both ends.
void row_contexts(const std::uint8_t* up, const std::uint8_t* back, std::uint32_t nx, std::uint8_t* padded,
                  std::uint8_t* contexts);

// Visits a brick's rows in raster order from row `first` (y + z·e_y) on,
// with each row's contexts: visit(i, contexts, lengths + i) for the row
// starting at voxel i, which sets the bit lengths of its tokens before the
// next row's visit (the rows before `first` have theirs already).
template <class Visit>
void walk_rows(const BrickDims& d, std::uint8_t* lengths, Visit&& visit, std::size_t first = 0) {
  const std::size_t sy = d[0], sz = std::size_t{d[0]} * d[1];
  std::vector<std::uint8_t> zeros(d[0]), contexts(d[0]), padded(std::size_t{d[0]} + 2);
  std::size_t i = first * d[0];
  for (auto z = static_cast<std::uint32_t>(first / d[1]); z < d[2]; ++z)
    for (std::uint32_t y = z == first / d[1] ? static_cast<std::uint32_t>(first % d[1]) : 0; y < d[1]; ++y, i += d[0]) {
      row_contexts(y ? lengths + i - sy : zeros.data(), z ? lengths + i - sz : zeros.data(), d[0], padded.data(),
                   contexts.data());
      visit(i, contexts.data(), lengths + i);
    }
}

// floor(x / f) for x below 2^32 and f in 1 .. 2^12, the rANS encoders'
// division: the high word of x times ceil(2^64 / f) from a table (f = 1,
// whose reciprocal does not fit, is x itself). The division instruction was
// a sixth of coder 2's encoding time.
std::uint32_t divide_by_frequency(std::uint32_t x, std::uint32_t f);

// The sum of bits_below_token over tokens[0 .. n) (each below 32).
std::uint64_t count_bits_below(const std::uint8_t* tokens, std::size_t n);

// Writes the bits below tokens[0 .. n) of residuals[0 .. n), LSB first, the
// last byte's unused high bits 0, from `to`; returns the end of those
// bytes. Writes up to 8 bytes past that end: `to` has room for
// (count_bits_below(tokens, n) + 7) / 8 + 8 bytes. Eight voxels a step with AVX2
// where the processor has it.
std::uint8_t* put_bits_below(const std::uint8_t* tokens, const std::uint16_t* residuals, std::size_t n,
                             std::uint8_t* to);

// residuals[i] for i in [0, n) from tokens[i] (each below 32) and the bits
// below them, LSB first, in bits[0 .. size). The caller has checked that
// the stream holds count_bits_below(tokens, n) bits: nothing is read past
// bits + size. Eight voxels a step with AVX2 where the processor has it.
void take_bits_below(const std::uint8_t* tokens, std::size_t n, const std::uint8_t* bits, std::size_t size,
                     std::uint16_t* residuals);

}  // namespace ivol::detail
