// Value encodings of the value array (spec §9).
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

namespace ivol {

enum class ValueEncoding : std::uint8_t { Binary16 = 1, UInt16 = 2, Float32 = 3 };

std::size_t encoding_width(ValueEncoding encoding);
const char* encoding_name(ValueEncoding encoding);  // "binary16", "uint16", "float32"
std::optional<ValueEncoding> parse_encoding(std::string_view name);
bool is_known_encoding(std::uint8_t code);

// The stored bits of a value (zero-extended to 32 bits) from a real number,
// rounded as §9 prescribes.
std::uint32_t encode_value(ValueEncoding encoding, double value);
// The decoded number held by stored bits (exact).
double decode_value(ValueEncoding encoding, std::uint32_t bits);

}  // namespace ivol
