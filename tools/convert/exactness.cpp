#include "exactness.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <sstream>

#include "ivol/binary16.hpp"
#include "ivol/error.hpp"

namespace ivol::convert {
namespace {

std::string number(double v) {
  std::ostringstream s;
  s.precision(9);
  s << v;
  return s.str();
}

std::uint32_t float_bits(float f) {
  std::uint32_t u;
  std::memcpy(&u, &f, 4);
  return u;
}

std::uint32_t load_le(const std::uint8_t* p, std::size_t width) {
  std::uint32_t v = 0;
  for (std::size_t b = 0; b < width; ++b) v |= std::uint32_t{p[b]} << (8 * b);
  return v;
}

void store(std::uint8_t* out, const void* value, std::size_t size) { std::memcpy(out, value, size); }

void integer_range(SampleType type, double& lo, double& hi) {
  switch (type) {
    case SampleType::UInt8:
      lo = 0, hi = 255;
      return;
    case SampleType::UInt16:
      lo = 0, hi = 65535;
      return;
    case SampleType::Int16:
      lo = -32768, hi = 32767;
      return;
    default:
      lo = -INFINITY, hi = INFINITY;
  }
}

// float32 bits -> binary16, counting what the binary16 does not hold.
std::uint16_t to_binary16_counted(float f, LossTally& loss) {
  const std::uint16_t h = float_to_binary16_keep_nan(f);
  const float back = binary16_to_float(h);
  if (float_bits(back) == float_bits(f)) return h;
  if (std::isnan(f)) {
    ++loss.voxels;
    ++loss.nan_payloads;
  } else if (std::isinf(back)) {
    loss.add_out_of_range(f, back);
  } else {
    loss.add(f, back);
  }
  return h;
}

// A physical value (binary64) as a sample of `type`, counting the change.
void physical_to_sample(double v, SampleType type, std::uint8_t* out, LossTally& loss) {
  switch (type) {
    case SampleType::Float32: {
      const auto f = static_cast<float>(v);
      if (!std::isnan(v) && static_cast<double>(f) != v) {
        if (std::isinf(f))
          loss.add_out_of_range(v, f);
        else
          loss.add(v, f);
      }
      store(out, &f, 4);
      return;
    }
    case SampleType::Float16: {
      const std::uint16_t h = double_to_binary16(v);
      const double back = binary16_to_double(h);
      if (!std::isnan(v) && back != v) {
        if (std::isinf(back))
          loss.add_out_of_range(v, back);
        else
          loss.add(v, back);
      }
      store(out, &h, 2);
      return;
    }
    default:
      break;
  }
  double lo, hi;
  integer_range(type, lo, hi);
  double r = 0.0;
  if (std::isnan(v)) {
    ++loss.voxels;
    ++loss.nans;
  } else {
    r = std::min(hi, std::max(lo, std::nearbyint(v)));
    if (v < lo || v > hi)
      loss.add_out_of_range(v, r);
    else if (r != v)
      loss.add(v, r);
  }
  if (type == SampleType::UInt8) {
    *out = static_cast<std::uint8_t>(r);
  } else if (type == SampleType::UInt16) {
    const auto u = static_cast<std::uint16_t>(r);
    store(out, &u, 2);
  } else {
    const auto s = static_cast<std::int16_t>(r);
    store(out, &s, 2);
  }
}

}  // namespace

void LossTally::merge(const LossTally& o) {
  if (o.out_of_range) {
    lowest = out_of_range ? std::min(lowest, o.lowest) : o.lowest;
    highest = out_of_range ? std::max(highest, o.highest) : o.highest;
  }
  voxels += o.voxels;
  max_error = std::max(max_error, o.max_error);
  out_of_range += o.out_of_range;
  nans += o.nans;
  nan_payloads += o.nan_payloads;
  signed_zeros += o.signed_zeros;
}

void LossTally::add(double from, double to) {
  ++voxels;
  double error = std::fabs(to - from);
  if (std::isnan(error)) error = INFINITY;  // a NaN became a number, or the reverse
  if (error > max_error) max_error = error;
}

void LossTally::add_out_of_range(double from, double to) {
  lowest = out_of_range ? std::min(lowest, from) : from;
  highest = out_of_range ? std::max(highest, from) : from;
  ++out_of_range;
  add(from, to);
}

std::string sample_range(SampleType type) {
  switch (type) {
    case SampleType::UInt8:
      return "0..255";
    case SampleType::UInt16:
      return "0..65535";
    case SampleType::Int16:
      return "-32768..32767";
    case SampleType::Float16:
      return "-65504..65504";
    case SampleType::Float32:
      return "-3.4e38..3.4e38";
  }
  return "?";
}

std::string describe_loss(const LossTally& loss, std::uint64_t total, const std::string& target) {
  std::string text = std::to_string(loss.voxels) + " of " + std::to_string(total) + " voxels change (largest error " +
                     number(loss.max_error);
  if (loss.out_of_range)
    text += "; " + std::to_string(loss.out_of_range) + " values in [" + number(loss.lowest) + ", " +
            number(loss.highest) + "] do not fit in " + target;
  if (loss.nans) text += "; " + std::to_string(loss.nans) + " NaN, which no integer holds";
  if (loss.nan_payloads) text += "; " + std::to_string(loss.nan_payloads) + " NaN lose their payload bits";
  if (loss.signed_zeros) text += "; " + std::to_string(loss.signed_zeros) + " -0 become +0";
  return text + ")";
}

void refuse_loss(const LossTally& loss, std::uint64_t total, const std::string& what, const std::string& target,
                 const std::string& hint) {
  if (loss.exact()) return;
  throw Error(ErrorClass::InvalidArgument,
              what + " is not exact: " + describe_loss(loss, total, target) + "; nothing written. " +
                  (hint.empty() ? std::string() : hint + " is exact; ") + "--allow-lossy accepts the loss");
}

void stored_to_samples(const VolumeLayout& layout, const std::uint8_t* stored, std::uint64_t count, SampleType type,
                       std::uint8_t* out, LossTally& loss) {
  const ValueEncoding encoding = layout.encoding;
  const std::size_t width = encoding_width(encoding);
  const std::size_t size = sample_size(type);
  const bool identity = layout.value_scale == 1.0 && layout.value_offset == 0.0;
  const bool same = identity && ((encoding == ValueEncoding::Binary16 && type == SampleType::Float16) ||
                                 (encoding == ValueEncoding::Float32 && type == SampleType::Float32) ||
                                 (encoding == ValueEncoding::UInt16 && type == SampleType::UInt16));
#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__
  if (same) {  // the stored bits are the samples' (both little-endian here): one copy, not a call a sample
    std::memcpy(out, stored, count * size);
    return;
  }
#endif
  for (std::uint64_t i = 0; i < count; ++i) {
    const std::uint32_t bits = load_le(stored + i * width, width);
    std::uint8_t* o = out + i * size;
    if (same) {
      store(o, &bits, size);  // little-endian host: the low bytes are the value
    } else if (identity && encoding == ValueEncoding::Binary16 && type == SampleType::Float32) {
      const float f = binary16_to_float(static_cast<std::uint16_t>(bits));  // exact, payloads included
      store(o, &f, 4);
    } else if (identity && encoding == ValueEncoding::Float32 && type == SampleType::Float16) {
      float f;
      std::memcpy(&f, &bits, 4);
      const std::uint16_t h = to_binary16_counted(f, loss);
      store(o, &h, 2);
    } else {
      physical_to_sample(layout.physical(decode_value(encoding, bits)), type, o, loss);
    }
  }
}

bool always_exact(const VolumeLayout& layout, SampleType type) {
  if (layout.value_scale != 1.0) return false;
  const bool to_float = type == SampleType::Float32;
  switch (layout.encoding) {
    case ValueEncoding::Binary16:
      return layout.value_offset == 0.0 && (to_float || type == SampleType::Float16);
    case ValueEncoding::Float32:
      return layout.value_offset == 0.0 && to_float;
    case ValueEncoding::UInt16:
      if (layout.value_offset == 0.0) return to_float || type == SampleType::UInt16;
      return layout.value_offset == -32768.0 && (to_float || type == SampleType::Int16);
  }
  return false;
}

void tally_encoding(ValueEncoding encoding, const float* values, std::uint64_t count, LossTally& loss) {
  if (encoding == ValueEncoding::Float32) return;
  std::uint8_t scratch[2];
  for (std::uint64_t i = 0; i < count; ++i) {
    if (encoding == ValueEncoding::Binary16)
      to_binary16_counted(values[i], loss);
    else
      physical_to_sample(values[i], SampleType::UInt16, scratch, loss);
  }
}

}  // namespace ivol::convert
