#include "dense_volume.hpp"

#include <cstring>

#include "ivol/binary16.hpp"
#include "sizes.hpp"

namespace ivol::convert {

const char* sample_type_name(SampleType type) {
  switch (type) {
    case SampleType::UInt8:
      return "u8";
    case SampleType::UInt16:
      return "u16";
    case SampleType::Int16:
      return "i16";
    case SampleType::Float16:
      return "f16";
    case SampleType::Float32:
      return "f32";
  }
  return "?";
}

bool parse_sample_type(const std::string& name, SampleType& out) {
  for (SampleType t :
       {SampleType::UInt8, SampleType::UInt16, SampleType::Int16, SampleType::Float16, SampleType::Float32})
    if (name == sample_type_name(t)) {
      out = t;
      return true;
    }
  return false;
}

std::size_t sample_size(SampleType type) {
  switch (type) {
    case SampleType::UInt8:
      return 1;
    case SampleType::UInt16:
    case SampleType::Int16:
    case SampleType::Float16:
      return 2;
    case SampleType::Float32:
      return 4;
  }
  return 0;
}

double DenseVolume::value(std::uint64_t i) const {
  const std::uint8_t* p = data.data() + i * sample_size(type);
  switch (type) {
    case SampleType::UInt8:
      return *p;
    case SampleType::UInt16: {
      std::uint16_t v;
      std::memcpy(&v, p, 2);
      return v;
    }
    case SampleType::Int16: {
      std::int16_t v;
      std::memcpy(&v, p, 2);
      return v;
    }
    case SampleType::Float16: {
      std::uint16_t v;
      std::memcpy(&v, p, 2);
      return binary16_to_double(v);
    }
    case SampleType::Float32: {
      float v;
      std::memcpy(&v, p, 4);
      return v;
    }
  }
  return 0.0;
}

std::vector<float> DenseVolume::to_float() const {
  std::vector<float> out(voxel_count());
  if (type == SampleType::Float32) {
    std::memcpy(out.data(), data.data(), out.size() * 4);
    return out;
  }
  for (std::uint64_t i = 0; i < out.size(); ++i) out[i] = static_cast<float>(value(i));
  return out;
}

DenseVolume make_dense(const Dims& dims, SampleType type) {
  DenseVolume v;
  v.dims = dims;
  v.type = type;
  checked_resize(v.data, slab_bytes(dims, dims[2], type, "a dense volume of " + dims_text(dims)),
                 "a dense volume of " + dims_text(dims) + " " + sample_type_name(type));
  return v;
}

DenseVolume shape_of(const DenseVolume& volume) {
  DenseVolume shape;
  shape.dims = volume.dims;
  shape.type = volume.type;
  shape.voxel_size = volume.voxel_size;
  shape.origin = volume.origin;
  shape.unit = volume.unit;
  shape.has_geometry = volume.has_geometry;
  shape.quantity = volume.quantity;
  shape.value_unit = volume.value_unit;
  shape.provenance = volume.provenance;
  shape.voxel_size_from = volume.voxel_size_from;
  shape.origin_from = volume.origin_from;
  shape.unit_from = volume.unit_from;
  shape.quantity_from = volume.quantity_from;
  shape.notes = volume.notes;
  return shape;
}

}  // namespace ivol::convert
