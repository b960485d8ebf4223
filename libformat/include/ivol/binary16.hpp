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

}  // namespace ivol
