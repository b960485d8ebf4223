// A dense volume as foreign formats hold it: the common ground of the
// converters (raw, TIFF, HDF5, OpenVDB) and the .ivol import and export.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "ivol/geometry.hpp"

namespace ivol::convert {

enum class SampleType { UInt8, UInt16, Int16, Float16, Float32 };

const char* sample_type_name(SampleType type);  // "u8", "u16", "i16", "f16", "f32"
bool parse_sample_type(const std::string& name, SampleType& out);
std::size_t sample_size(SampleType type);

struct DenseVolume {
  Dims dims{0, 0, 0};
  SampleType type = SampleType::Float32;
  // Samples, [z][y][x] with x fastest, native byte order, sample_size() each.
  std::vector<std::uint8_t> data;
  std::array<double, 3> voxel_size{1.0, 1.0, 1.0};
  std::array<double, 3> origin{0.0, 0.0, 0.0};  // centre of voxel (0, 0, 0)
  std::string unit = "mm";
  bool has_geometry = false;  // the source gave voxel size / origin

  // What the source says about its values and history; empty where it says
  // nothing. provenance is a JSON object's text (ivol's metadata §11).
  std::string quantity;
  std::string value_unit;
  std::string provenance;
  // Where voxel_size, origin and unit came from, for the conversion summary
  // (e.g. "OME-TIFF PhysicalSize"); empty: the source does not say.
  std::string voxel_size_from;
  std::string origin_from;
  std::string unit_from;
  std::string quantity_from;       // of quantity and value_unit
  std::vector<std::string> notes;  // what the reader noticed (skipped files, ...)

  std::uint64_t voxel_count() const { return ivol::voxel_count(dims); }
  double value(std::uint64_t index) const;  // any sample type, as a number
  std::vector<float> to_float() const;
};

DenseVolume make_dense(const Dims& dims, SampleType type);
// Everything but the samples: dims, type, geometry, metadata and notes.
DenseVolume shape_of(const DenseVolume& volume);

}  // namespace ivol::convert
