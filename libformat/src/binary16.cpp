#include "ivol/binary16.hpp"

#include <cmath>
#include <cstring>

namespace ivol {
namespace {

std::uint32_t float_bits(float f) {
  std::uint32_t u;
  std::memcpy(&u, &f, 4);
  return u;
}

float bits_float(std::uint32_t u) {
  float f;
  std::memcpy(&f, &u, 4);
  return f;
}

constexpr std::uint16_t kCanonicalNan = 0x7E00;

}  // namespace

float binary16_to_float(std::uint16_t h) {
  const std::uint32_t sign = static_cast<std::uint32_t>(h & 0x8000u) << 16;
  const std::uint32_t exponent = (h >> 10) & 0x1Fu;
  const std::uint32_t mantissa = h & 0x3FFu;
  if (exponent == 0) {
    // Zero or subnormal: mantissa · 2^-24, exact in binary32.
    const float magnitude = static_cast<float>(mantissa) * 5.9604644775390625e-8f;
    return sign ? -magnitude : magnitude;
  }
  if (exponent == 31) return bits_float(sign | 0x7F800000u | (mantissa << 13));
  return bits_float(sign | ((exponent + 112) << 23) | (mantissa << 13));
}

double binary16_to_double(std::uint16_t bits) { return static_cast<double>(binary16_to_float(bits)); }

std::uint16_t float_to_binary16(float value) {
  // Branch-light rounding on the bit pattern (after F. Giesen's
  // float_to_half_fast3_rtne); exhaustively tested against double_to_binary16.
  constexpr std::uint32_t kF32Infinity = 255u << 23;
  constexpr std::uint32_t kF16Overflow = (127u + 16u) << 23;  // 65536: anything above rounds to inf
  constexpr std::uint32_t kDenormMagic = ((127u - 15u) + (23u - 10u) + 1u) << 23;
  std::uint32_t x = float_bits(value);
  const std::uint32_t sign = x & 0x80000000u;
  x ^= sign;
  std::uint16_t out;
  if (x >= kF16Overflow) {
    if (x > kF32Infinity) return kCanonicalNan;
    out = 0x7C00;
  } else if (x < (113u << 23)) {
    // Result is subnormal or zero: let the FPU round by adding a magic number.
    const float shifted = bits_float(x) + bits_float(kDenormMagic);
    out = static_cast<std::uint16_t>(float_bits(shifted) - kDenormMagic);
  } else {
    const std::uint32_t mantissa_odd = (x >> 13) & 1u;
    x += (static_cast<std::uint32_t>(15 - 127) << 23) + 0xFFFu;
    x += mantissa_odd;
    out = static_cast<std::uint16_t>(x >> 13);
  }
  return static_cast<std::uint16_t>(out | (sign >> 16));
}

std::uint16_t float_to_binary16_keep_nan(float value) {
  const std::uint32_t x = float_bits(value);
  if ((x & 0x7FFFFFFFu) <= 0x7F800000u) return float_to_binary16(value);
  std::uint32_t payload = (x >> 13) & 0x3FFu;
  if (payload == 0) payload = 0x200u;
  return static_cast<std::uint16_t>(((x >> 16) & 0x8000u) | 0x7C00u | payload);
}

std::uint16_t float_to_binary16_upward(float value) {
  // Binary16's normal range (2^-14 up to below 2^16, where a positive value
  // carries into +inf): rebias the exponent and keep the top 10 mantissa
  // bits; a positive value with any lower bit set goes one step up, a
  // negative one's magnitude is cut (toward +inf either way).
  const std::uint32_t x = float_bits(value);
  const std::uint32_t a = x & 0x7FFFFFFFu;
  if (a >= 0x38800000u && a < 0x47800000u) {
    const std::uint32_t kept = (a - 0x38000000u) >> 13;
    if (x & 0x80000000u) return static_cast<std::uint16_t>(0x8000u | kept);
    return static_cast<std::uint16_t>(kept + ((a & 0x1FFFu) != 0));
  }
  std::uint16_t h = float_to_binary16(value);
  if (std::isnan(value) || !(binary16_to_float(h) < value)) return h;
  // The next binary16 number up: -0 goes to the least positive subnormal,
  // a negative one's magnitude shrinks, a positive one's grows (65504 to +inf).
  if (h == 0x8000) return 0x0001;
  return static_cast<std::uint16_t>(h & 0x8000 ? h - 1 : h + 1);
}

std::uint16_t double_to_binary16(double value) {
  if (std::isnan(value)) return kCanonicalNan;
  const std::uint16_t sign = std::signbit(value) ? 0x8000 : 0;
  const double a = std::fabs(value);
  if (a >= 65520.0) return static_cast<std::uint16_t>(sign | 0x7C00);
  if (a < 6.103515625e-05) {  // below 2^-14: subnormal, units of 2^-24
    const double units = std::nearbyint(a * 16777216.0);
    return static_cast<std::uint16_t>(sign | static_cast<std::uint16_t>(units));
  }
  int e2 = 0;
  std::frexp(a, &e2);                                                 // a = f · 2^e2, f in [0.5, 1)
  int exponent = e2 - 1;                                              // a in [2^exponent, 2^(exponent+1))
  double significand = std::nearbyint(std::ldexp(a, 10 - exponent));  // in [1024, 2048]
  if (significand >= 2048.0) {
    significand = 1024.0;
    ++exponent;
  }
  if (exponent > 15) return static_cast<std::uint16_t>(sign | 0x7C00);
  const auto bits = static_cast<std::uint16_t>(((exponent + 15) << 10) | (static_cast<int>(significand) - 1024));
  return static_cast<std::uint16_t>(sign | bits);
}

}  // namespace ivol
