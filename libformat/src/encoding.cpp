#include "ivol/encoding.hpp"

#include <cmath>
#include <cstring>

#include "ivol/binary16.hpp"

namespace ivol {

std::size_t encoding_width(ValueEncoding encoding) { return encoding == ValueEncoding::Float32 ? 4 : 2; }

const char* encoding_name(ValueEncoding encoding) {
  switch (encoding) {
    case ValueEncoding::Binary16:
      return "binary16";
    case ValueEncoding::UInt16:
      return "uint16";
    case ValueEncoding::Float32:
      return "float32";
  }
  return "unknown";
}

std::optional<ValueEncoding> parse_encoding(std::string_view name) {
  if (name == "binary16" || name == "f16" || name == "half") return ValueEncoding::Binary16;
  if (name == "uint16" || name == "u16") return ValueEncoding::UInt16;
  if (name == "float32" || name == "f32") return ValueEncoding::Float32;
  return std::nullopt;
}

bool is_known_encoding(std::uint8_t code) { return code >= 1 && code <= 3; }

std::uint32_t encode_value(ValueEncoding encoding, double value) {
  switch (encoding) {
    case ValueEncoding::Binary16:
      return double_to_binary16(value);
    case ValueEncoding::UInt16: {
      if (std::isnan(value)) return 0;               // cannot occur for averages of codes
      const double rounded = std::nearbyint(value);  // ties to even in the default mode
      if (rounded <= 0.0) return 0;
      if (rounded >= 65535.0) return 65535;
      return static_cast<std::uint32_t>(rounded);
    }
    case ValueEncoding::Float32: {
      if (std::isnan(value)) return 0x7FC00000u;
      // At or above the midpoint between FLT_MAX and 2^128 IEEE rounds to
      // infinity; C++ leaves that conversion undefined, so do it here.
      constexpr double kOverflowMidpoint = 0x1.ffffffp127;
      if (std::fabs(value) >= kOverflowMidpoint) return std::signbit(value) ? 0xFF800000u : 0x7F800000u;
      const auto f = static_cast<float>(value);  // round to nearest even
      std::uint32_t bits;
      std::memcpy(&bits, &f, 4);
      return bits;
    }
  }
  return 0;
}

double decode_value(ValueEncoding encoding, std::uint32_t bits) {
  switch (encoding) {
    case ValueEncoding::Binary16:
      return binary16_to_double(static_cast<std::uint16_t>(bits));
    case ValueEncoding::UInt16:
      return static_cast<double>(bits & 0xFFFFu);
    case ValueEncoding::Float32: {
      float f;
      std::memcpy(&f, &bits, 4);
      return f;
    }
  }
  return 0.0;
}

}  // namespace ivol
