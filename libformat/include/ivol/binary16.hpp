// IEEE 754 binary16 ("half") conversions with round-to-nearest-even, as the
// spec (§9) requires for the binary16 value encoding.
#pragma once

#include <cstdint>

namespace ivol {

// Exact: every binary16 number is a binary32 and a binary64 number.
float binary16_to_float(std::uint16_t bits);
double binary16_to_double(std::uint16_t bits);

// Correctly rounded (nearest, ties to even); overflow gives infinity; any NaN
// gives the canonical 0x7E00.
std::uint16_t float_to_binary16(float value);
std::uint16_t double_to_binary16(double value);

// As float_to_binary16, except that a NaN keeps its sign and the top 10 bits
// of its payload (the quiet bit set when those are all zero): the bits a leaf
// stores (spec §9 passes any leaf NaN through), so that binary16 -> float ->
// binary16 gives back every one of the 65 536 bit patterns.
std::uint16_t float_to_binary16_keep_nan(float value);

// The least binary16 number not below `value` (rounded toward +infinity):
// binary16_to_float of it is >= value, so a comparison "above t" that holds
// for the float holds for it too (the detection preview's cells, issue 23).
// Above 65504 gives +infinity; any NaN gives the canonical 0x7E00.
std::uint16_t float_to_binary16_upward(float value);

}  // namespace ivol
