// Reading and writing dense volumes slab by slab (ranges of z slices), so that
// converters hold one slab at a time, never the whole volume.
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "dense_volume.hpp"
#include "raw_io.hpp"
#include "tiff_folder.hpp"

namespace ivol::convert {

class SlabReader {
 public:
  virtual ~SlabReader() = default;
  // dims, sample type and geometry; `data` stays empty.
  const DenseVolume& shape() const { return shape_; }
  // Reads slices z0 .. z0 + count into `out` ([z][y][x], native byte order).
  virtual void read(std::uint32_t z0, std::uint32_t count, void* out) = 0;

 protected:
  DenseVolume shape_;
};

class SlabWriter {
 public:
  virtual ~SlabWriter() = default;  // unfinished: nothing left at the target
  // Appends the next `count` slices.
  virtual void write(const void* samples, std::uint32_t count) = 0;
  // After the last slice: the file appears at its path.
  virtual void finish() = 0;
};

std::unique_ptr<SlabReader> open_raw_slabs(const std::string& path, const RawLayout& layout);
std::unique_ptr<SlabReader> open_tiff_slabs(const std::string& path_or_folder, const TiffFolderOptions& options = {});
// A volume already in memory (formats read whole, e.g. OpenVDB): owned, or
// only viewed (the volume must outlive the reader).
std::unique_ptr<SlabReader> memory_slabs(DenseVolume volume);
std::unique_ptr<SlabReader> view_slabs(const DenseVolume& volume);

std::unique_ptr<SlabWriter> create_raw_slabs(const std::string& path, const DenseVolume& shape, bool big_endian);
std::unique_ptr<SlabWriter> create_tiff_slabs(const std::string& path, const DenseVolume& shape, bool compress = true);

}  // namespace ivol::convert
