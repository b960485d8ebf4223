// HDF5 import and export of dense volumes (DXchange / tomopy style: one 3-D
// dataset, by default /exchange/data).
//
// Axis order: HDF5 stores C order, so a dataset of shape (nz, ny, nx) holds
// [z][y][x] with x fastest, exactly as DenseVolume does; no transposition.
//
// Geometry attributes, on the dataset itself (DXchange has no settled place
// for the voxel size of a reconstruction, so we read the common spellings and
// write one):
//   voxel_size  float64 x 3, in the dataset's axis order (z, y, x), or a
//               single number for isotropic voxels;
//   pixel_size  a single number, isotropic, if voxel_size is absent (DXchange
//               and tomopy users often write this);
//   origin      float64 x 3, (z, y, x), world position of the centre of voxel
//               (0, 0, 0); absent means (0, 0, 0);
//   unit        string (also read: units), e.g. "mm"; absent keeps "mm".
//   quantity, value_unit
//               strings: what the values are (ivol's value.quantity and
//               value.unit), e.g. "linear_attenuation", "1/mm";
//   provenance  string: a JSON object, ivol's provenance (volume_metadata.hpp).
// A file ITK wrote (HDF5ImageIO: /ITKImage/0/VoxelData with Spacing, Origin
// and Directions datasets beside it, x-y-z order, ITK's millimetres) is read
// with that geometry, also when no dataset is named (the default
// /exchange/data is absent there); a Directions other than the identity is
// refused.
// Without voxel_size and pixel_size, DXchange's
// /measurement/instrument/detector/actual_pixel_size_x (and _y, for z) give
// the voxel size: x = y = actual_pixel_size_x, z = actual_pixel_size_y, in
// their "units" attribute (metres without one), converted to mm.
// has_geometry is true when one of those is present, unless the provenance
// says "voxel_size_known": false. write_hdf5 writes voxel_size, origin and
// unit only for a volume with has_geometry; quantity, value_unit and
// provenance when they are not empty.
#pragma once

#include <array>
#include <string>

#include "dense_volume.hpp"
#include "slab_io.hpp"

namespace ivol::convert {

// What the file held, for reports: read_hdf5 may convert on the way.
struct Hdf5SourceInfo {
  std::string dataset;                               // the dataset read (the default may resolve to ITK's)
  std::string stored_type;                           // "u8", "u16", "i16", "f16", "f32", "f64"
  bool narrowed_to_f32 = false;                      // float64 samples were rounded to float32
  bool chunked = false;                              // chunked layout (else contiguous or compact)
  std::array<unsigned long long, 3> chunk{0, 0, 0};  // (z, y, x), when chunked
  std::string filters;                               // e.g. "shuffle,deflate", empty for none
};

inline constexpr const char* kDefaultDataset = "/exchange/data";

// Reads a 3-D dataset of u8, u16, i16, 16-bit float, f32 or f64 (returned as
// f32, reported in *source). Any layout and any filter the HDF5 library has.
// Throws ivol::Error: Io (cannot open), Malformed (not an HDF5 file, bad
// geometry attribute), InvalidArgument (no such dataset: the message lists
// the 3-D datasets there are; not 3-D; unsupported sample type).
DenseVolume read_hdf5(const std::string& path, const std::string& dataset = "/exchange/data",
                      Hdf5SourceInfo* source = nullptr);

// The same, slab by slab (hyperslab reads): memory holds one slab.
// libhdf5 runs in a child process of its own (isolated_worker.hpp): a crash
// of the library on a damaged file is an ivol::Error(Malformed) naming it,
// not the end of ivol. read_hdf5 reads through it too.
// The child may allocate `memory_bytes` (0: kDefaultChildMemory, 1 GiB)
// besides the slab it returns; a file that needs more (a small dataset in
// one huge compressed chunk) is ivol::Error(LimitExceeded).
std::unique_ptr<SlabReader> open_hdf5_slabs(const std::string& path, const std::string& dataset = "/exchange/data",
                                            Hdf5SourceInfo* source = nullptr, std::uint64_t memory_bytes = 0);
// The same in this process, as the child runs it; for the fuzz harness,
// which must see the library's crashes to tell them from ivol's. HDF5's
// chunk cache takes at most a quarter of `memory_bytes` (0: 1 GiB).
std::unique_ptr<SlabReader> open_hdf5_slabs_in_process(const std::string& path,
                                                       const std::string& dataset = "/exchange/data",
                                                       Hdf5SourceInfo* source = nullptr,
                                                       std::uint64_t memory_bytes = 0);

// Writes a chunked (64^3, clipped to the volume) dataset with the shuffle and
// deflate filters (deflate_level 0: chunked, no filters), creating the groups
// on the way, samples little-endian. Writes a temporary file in the same
// directory and renames it into place: never a partial file at `path`.
void write_hdf5(const DenseVolume& volume, const std::string& path, const std::string& dataset = "/exchange/data",
                int deflate_level = 4);

// The same, slab by slab. band_rows > 0: the samples come by write_rows in
// bands of that many rows (the last of a slice may be shorter); chunks are
// then one slice deep and min(band_rows, 64) rows high (band_rows above 64
// must be a multiple of 64), so that every band writes whole chunks and
// none is read back, decompressed and written again.
std::unique_ptr<SlabWriter> create_hdf5_slabs(const std::string& path, const DenseVolume& shape,
                                              const std::string& dataset = "/exchange/data", int deflate_level = 4,
                                              std::uint32_t band_rows = 0);

}  // namespace ivol::convert
