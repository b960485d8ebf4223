#include "sample_values.hpp"

#include <cstring>

#include "ivol/binary16.hpp"

namespace ivol::convert {

void to_float(const DenseVolume& shape, const std::uint8_t* samples, std::uint64_t count, float* out) {
  const std::size_t size = sample_size(shape.type);
  for (std::uint64_t i = 0; i < count; ++i) {
    const std::uint8_t* p = samples + i * size;
    switch (shape.type) {
      case SampleType::UInt8:
        out[i] = *p;
        break;
      case SampleType::UInt16: {
        std::uint16_t v;
        std::memcpy(&v, p, 2);
        out[i] = v;
        break;
      }
      case SampleType::Int16: {
        std::int16_t v;
        std::memcpy(&v, p, 2);
        out[i] = v;
        break;
      }
      case SampleType::Float16: {
        std::uint16_t v;
        std::memcpy(&v, p, 2);
        out[i] = binary16_to_float(v);
        break;
      }
      case SampleType::Float32:
        std::memcpy(&out[i], p, 4);
        break;
    }
  }
}

void to_codes(SampleType type, const std::uint8_t* samples, std::uint64_t count, double offset, std::uint16_t* out) {
  for (std::uint64_t i = 0; i < count; ++i) {
    const std::uint8_t* p = samples + i * sample_size(type);
    double v = 0;
    if (type == SampleType::UInt8) {
      v = *p;
    } else if (type == SampleType::UInt16) {
      std::uint16_t u;
      std::memcpy(&u, p, 2);
      v = u;
    } else {
      std::int16_t t;
      std::memcpy(&t, p, 2);
      v = t;
    }
    out[i] = static_cast<std::uint16_t>(v - offset);
  }
}

}  // namespace ivol::convert
