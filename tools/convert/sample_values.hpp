// A slab's samples, of any input type, as what the writers take: float32
// values, or the uint16 encoding's codes (sample - offset).
#pragma once

#include <cstdint>

#include "dense_volume.hpp"

namespace ivol::convert {

void to_float(const DenseVolume& shape, const std::uint8_t* samples, std::uint64_t count, float* out);
// Integer samples (u8, u16, i16) as codes; the caller has checked the type.
void to_codes(SampleType type, const std::uint8_t* samples, std::uint64_t count, double offset, std::uint16_t* out);

}  // namespace ivol::convert
