// Raw volumes: bare samples, optionally after a header, in either byte order.
#pragma once

#include <string>

#include "dense_volume.hpp"

namespace ivol::convert {

struct RawLayout {
  Dims dims{0, 0, 0};
  SampleType type = SampleType::Float32;
  bool big_endian = false;
  std::uint64_t header_bytes = 0;  // skipped before the first sample
};

// Checks the file's size against the layout before reading anything.
DenseVolume read_raw(const std::string& path, const RawLayout& layout);
// Writes the samples [z][y][x] in the given byte order, through a temporary
// file renamed when complete.
void write_raw(const DenseVolume& volume, const std::string& path, bool big_endian = false);

}  // namespace ivol::convert
