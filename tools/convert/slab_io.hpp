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
  // Whether read_rows works: a source whose one slice may exceed the memory
  // budget (a TIFF page of 16384^2 from a few hundred KB of deflate) reads
  // it a band of rows at a time.
  virtual bool reads_rows() const { return false; }
  // Reads rows y0 .. y0 + rows of slice z into `out` ([y][x]); y0 + rows is
  // at most the slice's height.
  virtual void read_rows(std::uint32_t /*z*/, std::uint32_t /*y0*/, std::uint32_t /*rows*/, void* /*out*/) {}
  // Whether a read of more slices costs less per slice (a reconstruction's
  // slabs, HDF5 chunks spanning slices): the bricked importer then reads as
  // many as its memory budget holds; else (raw files, TIFF pages) a layer of
  // bricks at a time, into buffers that stay mapped and in cache.
  virtual bool thick_reads_pay() const { return true; }

 protected:
  DenseVolume shape_;
};

class SlabWriter {
 public:
  virtual ~SlabWriter() = default;  // unfinished: nothing left at the target
  // Appends the next `count` slices.
  virtual void write(const void* samples, std::uint32_t count) = 0;
  // Whether write_rows works (see SlabReader::reads_rows).
  virtual bool writes_rows() const { return false; }
  // Appends the next `rows` rows: slices in order, rows in order within a
  // slice; a slice is complete after its last row. Not mixed with write().
  virtual void write_rows(const void* /*samples*/, std::uint32_t /*rows*/) {}
  // After the last slice: the file appears at its path.
  virtual void finish() = 0;
  // Memory the writer holds through the whole run, already weighed against
  // the budget (an OpenVDB output's volume and tree): a source sizes its
  // slabs from what is left.
  virtual std::uint64_t held_bytes() const { return 0; }
};

// Where a writer fed by write_rows stands: the slices complete and the rows
// written of the next one.
struct RowPosition {
  std::uint32_t slices = 0;
  std::uint32_t rows = 0;
  void advance(std::uint32_t count, std::uint32_t height) {
    const std::uint64_t at = std::uint64_t{rows} + count;  // 64-bit: two heights near 2^32 must not wrap
    slices += static_cast<std::uint32_t>(at / height);
    rows = static_cast<std::uint32_t>(at % height);
  }
};

std::unique_ptr<SlabReader> open_raw_slabs(const std::string& path, const RawLayout& layout);
// memory_bytes (0: kDefaultMemoryBytes) bounds what libtiff may allocate at
// once and the tile a page is read by.
std::unique_ptr<SlabReader> open_tiff_slabs(const std::string& path_or_folder, const TiffFolderOptions& options = {},
                                            std::uint64_t memory_bytes = 0);
// A volume already in memory (formats read whole, e.g. OpenVDB): owned, or
// only viewed (the volume must outlive the reader).
std::unique_ptr<SlabReader> memory_slabs(DenseVolume volume);
std::unique_ptr<SlabReader> view_slabs(const DenseVolume& volume);

std::unique_ptr<SlabWriter> create_raw_slabs(const std::string& path, const DenseVolume& shape, bool big_endian);
std::unique_ptr<SlabWriter> create_tiff_slabs(const std::string& path, const DenseVolume& shape, bool compress = true);

}  // namespace ivol::convert
