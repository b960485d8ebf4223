#include "sample_values.hpp"

#include <cmath>
#include <cstring>
#include <string>

#include "ivol/binary16.hpp"
#include "ivol/error.hpp"

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

namespace {

// One loop per sample type, in integers, so that it vectorises: it runs on
// the converter's reading thread, before the layer's encoding can start.
template <class Sample>
void codes_of(const std::uint8_t* samples, std::uint64_t count, std::int32_t offset, std::uint16_t* out) {
  for (std::uint64_t i = 0; i < count; ++i) {
    Sample v;
    std::memcpy(&v, samples + i * sizeof(Sample), sizeof(Sample));
    out[i] = static_cast<std::uint16_t>(static_cast<std::int32_t>(v) - offset);
  }
}

}  // namespace

void to_codes(SampleType type, const std::uint8_t* samples, std::uint64_t count, double offset, std::uint16_t* out) {
  // The offsets a converter uses are whole numbers (0, or -32768 for int16).
  if (!(offset == std::floor(offset) && std::fabs(offset) <= 65536.0))
    throw Error(ErrorClass::InvalidArgument,
                "to_codes: the value offset " + std::to_string(offset) + " is not a whole number within 65536");
  const auto shift = static_cast<std::int32_t>(offset);
  switch (type) {
    case SampleType::UInt8:
      codes_of<std::uint8_t>(samples, count, shift, out);
      return;
    case SampleType::UInt16:
      if (shift == 0)
        std::memcpy(out, samples, count * 2);  // little-endian hosts, as every reader here
      else
        codes_of<std::uint16_t>(samples, count, shift, out);
      return;
    case SampleType::Int16:
      codes_of<std::int16_t>(samples, count, shift, out);
      return;
    default:
      throw Error(ErrorClass::InvalidArgument, "to_codes: only integer samples have codes");
  }
}

}  // namespace ivol::convert
