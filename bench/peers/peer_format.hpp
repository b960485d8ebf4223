// One storage format under test in peers_bench: how it writes a volume and
// how it reads the whole volume, a box and a 1/8-resolution preview back.
//
// Every format is measured through its own library (OpenVDB, the HDF5 C API,
// libtiff, POSIX I/O, libformat), never through ivol's converters, so that a
// peer is not slowed or helped by our code paths.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "ivol/geometry.hpp"

namespace peers {

// What a format is asked to hold. `values` is the reconstructed volume,
// [z][y][x] with x fastest, already rounded to binary16 (every format keeps
// exactly these values where it keeps a voxel). With `keep`, only voxels
// where keep[i] != 0 must survive; the others may be dropped or replaced by
// `background`.
struct VolumeCase {
  std::uint32_t n = 0;  // the volume is n^3
  const std::vector<float>* values = nullptr;
  const std::vector<std::uint8_t>* keep = nullptr;  // null: every voxel
  float background = 0.0f;
  std::uint64_t voxel_count() const { return std::uint64_t{n} * n * n; }
};

class PeerFormat {
 public:
  virtual ~PeerFormat() = default;
  virtual std::string name() const = 0;
  // What it stores, for the table: e.g. "half, blosc-lz4, active = kept".
  virtual std::string details() const = 0;
  // Writes `volume` at `path` (a file, or a folder for a TIFF stack).
  virtual void write(const VolumeCase& volume, const std::string& path) = 0;
  // Physical values of `box`, [z][y][x] with x fastest. Opens the file anew,
  // so that what it reads on open is counted with the box.
  virtual std::vector<float> read_box(const std::string& path, std::uint32_t n, const ivol::Box& box) = 0;
  // The whole volume at 1/factor resolution (means of factor^3 voxels). The
  // default reads everything and averages: what a format without levels of
  // detail has to do.
  virtual std::vector<float> read_preview(const std::string& path, std::uint32_t n, std::uint32_t factor);
};

// Means of factor^3 blocks of an n^3 volume ([z][y][x]); n a multiple of factor.
std::vector<float> downsample(const std::vector<float>& volume, std::uint32_t n, std::uint32_t factor);

// Bytes this process has read through read()/pread() so far (/proc/self/io
// rchar): the honest count for any library reading with system calls.
std::uint64_t bytes_read_by_process();
// Writes the file's (or folder's files') dirty pages and drops them from the
// page cache, so that the next read fetches from the disk what it needs.
void flush_and_evict(const std::string& path);
// Bytes of the file (or folder) now in the page cache (mincore): after an
// eviction and a read, what the read fetched from the disk, the kernel's
// readahead included.
std::uint64_t bytes_in_page_cache(const std::string& path);
// Size of a file, or the sum of the files in a folder.
std::uint64_t bytes_on_disk(const std::string& path);

// The formats, in table order. `keep_mode`: the volume comes with a keep mask.
std::vector<std::unique_ptr<PeerFormat>> ivol_formats(bool keep_mode);
std::vector<std::unique_ptr<PeerFormat>> vdb_formats();
std::vector<std::unique_ptr<PeerFormat>> hdf5_formats();
std::vector<std::unique_ptr<PeerFormat>> tiff_formats();
std::vector<std::unique_ptr<PeerFormat>> raw_formats();

// Library versions, for the report.
std::string vdb_version();
std::string hdf5_version();
std::string tiff_version();
// Whether HDF5 can load the blosc filter (Debian: hdf5-filter-plugin-blosc-serial).
bool hdf5_blosc_available();

}  // namespace peers

namespace peers {
// An uncompressed 16-bit unsigned TIFF stack (one file per z-slice): the
// input of the conversion benchmark, as scanners' software writes them.
void write_uint16_tiff_stack(const std::vector<std::uint16_t>& volume, std::uint32_t n, const std::string& folder);
}  // namespace peers
