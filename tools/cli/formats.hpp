// Which format a path names, and reading and writing dense volumes in it.
#pragma once

#include <string>

#include "dense_volume.hpp"
#include "raw_io.hpp"

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
};

convert::DenseVolume read_dense(const std::string& path, Format format, const ForeignOptions& options);
void write_dense(const convert::DenseVolume& volume, const std::string& path, Format format,
                 const ForeignOptions& options);

}  // namespace ivol::cli
