// Which format a path names, and opening it as a source or sink of slabs.
#pragma once

#include <memory>
#include <string>

#include "dense_volume.hpp"
#include "ivol_io.hpp"
#include "raw_io.hpp"
#include "slab_io.hpp"

namespace ivol::cli {

enum class Format { Ivol, Raw, Tiff, Hdf5, Vdb, MetaImage, Nrrd };

const char* format_name(Format format);
// The sample type an export to `to` keeps every value of the .ivol file in:
// float for OpenVDB, float32 where the format has no binary16 (MetaImage,
// NRRD), else the file's own.
convert::SampleType natural_export_type(Format to, const Reader& reader);
// By `name` when given (ivol, raw, tiff, hdf5, vdb, mha, nrrd), else by the path's
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
  // False: refuse an OpenVDB grid that would not hold every value, and an
  // HDF5 float64 input (read as float32).
  bool allow_lossy = true;
  bool allow_gaps = false;  // TIFF folder with missing slice numbers
  // Output written by write_rows in bands of this many rows (0: by slices);
  // the HDF5 writer fits its chunks to them.
  std::uint32_t band_rows = 0;
};

// Whether the output format can be written a band of rows at a time (every
// dense format but OpenVDB, whose grids are written whole).
bool writes_rows(Format format);

// The format written to `path`: `name` (--to) or the extension, which must
// agree: a known extension of another format is refused ("b.ivol --to raw"),
// an unknown one needs `name`. "-" (standard output) is raw. UsageError.
Format output_format(const std::string& path, const std::string& name, const char* option);

// A dense input, read slab by slab (OpenVDB grids are read whole); "-" is
// raw samples on standard input. With `rounded`: set when the reader rounds
// the stored samples (HDF5 float64).
std::unique_ptr<convert::SlabReader> open_source(const std::string& path, Format format, const ForeignOptions& options,
                                                 bool* rounded = nullptr);
// A dense output for a volume of `shape`, written slab by slab (OpenVDB
// grids are assembled in memory and written at finish()); "-" is raw samples
// on standard output.
std::unique_ptr<convert::SlabWriter> create_sink(const std::string& path, Format format,
                                                 const convert::DenseVolume& shape, const ForeignOptions& options);

// OpenVDB grids hold floats: refuses an integer `type` for OpenVDB output,
// naming `option` (UsageError).
void check_export_type(Format to, convert::SampleType type, const char* option);

// What export_from_ivol runs before finishing the output: unless
// `allow_lossy`, refuses a conversion that changed a value, naming `what`,
// the loss, `option` with the exact `natural` type when `type` is not it, and
// --allow-lossy.
convert::LossCheck exactness_check(bool allow_lossy, const std::string& what, convert::SampleType type,
                                   convert::SampleType natural, const char* option);

// Standard output cannot be taken back: when `output` is "-" and the export
// may change values, runs it first into nothing with `check`, which refuses
// before the first byte is written.
void check_before_streaming(const std::string& output, Reader& reader, const Box& box, unsigned lod,
                            convert::SampleType type, const convert::LossCheck& check, bool salvage);

}  // namespace ivol::cli
