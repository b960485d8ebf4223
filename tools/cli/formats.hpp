// Which format a path names, and opening it as a source or sink of slabs.
#pragma once

#include <memory>
#include <string>

#include "dense_volume.hpp"
#include "raw_io.hpp"
#include "slab_io.hpp"

namespace ivol::cli {

enum class Format { Ivol, Raw, Tiff, Hdf5, Vdb };

const char* format_name(Format format);
// By `name` when given (ivol, raw, tiff, hdf5, vdb), else by the path's
// extension (a folder is a TIFF stack). Throws InvalidArgument naming `option`.
Format detect_format(const std::string& path, const std::string& name, const char* option);

struct ForeignOptions {
  convert::RawLayout raw;  // for raw input
  bool raw_dims_given = false;
  bool big_endian = false;                 // for raw output
  std::string dataset = "/exchange/data";  // HDF5
  std::string grid;                        // OpenVDB; empty: the first float grid
  float background = 0.0f;                 // OpenVDB output
  std::uint64_t memory_bytes = 0;          // --memory; 0: the default (convert/sizes.hpp)
  bool allow_gaps = false;                 // TIFF folder with missing slice numbers
};

// The format written to `path`: `name` (--to) or the extension, which must
// agree: a known extension of another format is refused ("b.ivol --to raw"),
// an unknown one needs `name`. "-" (standard output) is raw. UsageError.
Format output_format(const std::string& path, const std::string& name, const char* option);

// A dense input, read slab by slab (OpenVDB grids are read whole); "-" is
// raw samples on standard input.
std::unique_ptr<convert::SlabReader> open_source(const std::string& path, Format format, const ForeignOptions& options);
// A dense output for a volume of `shape`, written slab by slab (OpenVDB
// grids are assembled in memory and written at finish()); "-" is raw samples
// on standard output.
std::unique_ptr<convert::SlabWriter> create_sink(const std::string& path, Format format,
                                                 const convert::DenseVolume& shape, const ForeignOptions& options);

}  // namespace ivol::cli
