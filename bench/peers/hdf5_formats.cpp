// HDF5 peers for peers_bench, through the HDF5 C API: a 3-D dataset of IEEE
// binary16 (a float type HDF5 builds from its fields, as h5py's float16),
// chunked 64^3 (what `ivol convert` and many tools write), with
//   - shuffle + deflate (built into libhdf5),
//   - blosc (filter 32001, Debian's hdf5-filter-plugin-blosc-serial) with
//     byte shuffle and its LZ4 codec at level 5 (blosc's default), or its
//     zstd codec at level 3 (ivol's level).
// The zstd filter proper (32015) is not packaged for Debian 12; blosc's zstd
// codec is how HDF5 users get zstd there.
//
// Values are converted to binary16 bits by our code and written with the
// file's type as the memory type (no HDF5 conversion), and read back the same
// way: the arithmetic of the conversion is the same for every format. With a
// keep mask the voxels outside it hold the background value, which chunked
// compression squeezes to almost nothing (HDF5 cannot drop voxels).
//
// Bytes read: /proc/self/io rchar around open + read + close (the sec2 driver
// reads with pread).
#include <hdf5.h>

#include <stdexcept>
#include <string>

#include "ivol/binary16.hpp"
#include "peer_format.hpp"

namespace peers {

namespace {

constexpr H5Z_filter_t kBloscFilter = 32001;
constexpr unsigned kBloscLz4 = 1;
constexpr unsigned kBloscZstd = 5;

void check(herr_t status, const char* what) {
  if (status < 0) throw std::runtime_error(std::string("HDF5: ") + what + " failed");
}

hid_t check_id(hid_t id, const char* what) {
  if (id < 0) throw std::runtime_error(std::string("HDF5: ") + what + " failed");
  return id;
}

// IEEE 754 binary16, little-endian: sign bit 15, exponent bits 10-14 (bias
// 15), mantissa bits 0-9.
hid_t binary16_type() {
  const hid_t type = check_id(H5Tcopy(H5T_IEEE_F32LE), "H5Tcopy");
  check(H5Tset_fields(type, 15, 10, 5, 0, 10), "H5Tset_fields");
  check(H5Tset_size(type, 2), "H5Tset_size");
  check(H5Tset_ebias(type, 15), "H5Tset_ebias");
  return type;
}

enum class Compression { Deflate, BloscLz4, BloscZstd };

class Hdf5Format : public PeerFormat {
 public:
  explicit Hdf5Format(Compression compression) : compression_(compression) {}
  std::string name() const override {
    switch (compression_) {
      case Compression::Deflate:
        return "HDF5 deflate";
      case Compression::BloscLz4:
        return "HDF5 blosc-lz4";
      case Compression::BloscZstd:
        return "HDF5 blosc-zstd";
    }
    return "";
  }
  std::string details() const override {
    switch (compression_) {
      case Compression::Deflate:
        return "binary16, chunks 64^3, shuffle + deflate 4";
      case Compression::BloscLz4:
        return "binary16, chunks 64^3, blosc lz4-5 + byte shuffle";
      case Compression::BloscZstd:
        return "binary16, chunks 64^3, blosc zstd-3 + byte shuffle";
    }
    return "";
  }

  void write(const VolumeCase& volume, const std::string& path) override {
    const std::uint32_t n = volume.n;
    std::vector<std::uint16_t> bits(volume.voxel_count());
    const float* values = volume.values->data();
    const std::uint8_t* keep = volume.keep ? volume.keep->data() : nullptr;
    const std::uint16_t background = ivol::float_to_binary16(volume.background);
    for (std::size_t i = 0; i < bits.size(); ++i)
      bits[i] = (!keep || keep[i]) ? ivol::float_to_binary16(values[i]) : background;

    const hid_t file = check_id(H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT), "H5Fcreate");
    const hsize_t dims[3] = {n, n, n};
    const hsize_t chunk[3] = {64, 64, 64};
    const hid_t space = check_id(H5Screate_simple(3, dims, nullptr), "H5Screate_simple");
    const hid_t properties = check_id(H5Pcreate(H5P_DATASET_CREATE), "H5Pcreate");
    check(H5Pset_chunk(properties, 3, chunk), "H5Pset_chunk");
    if (compression_ == Compression::Deflate) {
      check(H5Pset_shuffle(properties), "H5Pset_shuffle");
      check(H5Pset_deflate(properties, 4), "H5Pset_deflate");
    } else {
      // cd_values 0-3 are filled in by the filter; 4 level, 5 shuffle, 6 codec.
      // Optional: the filter fails on a chunk it cannot shrink (noise), and
      // HDF5 then stores that chunk as it is, as users of blosc do.
      const unsigned level = compression_ == Compression::BloscZstd ? 3 : 5;
      const unsigned codec = compression_ == Compression::BloscZstd ? kBloscZstd : kBloscLz4;
      const unsigned cd_values[7] = {0, 0, 0, 0, level, 1, codec};
      check(H5Pset_filter(properties, kBloscFilter, H5Z_FLAG_OPTIONAL, 7, cd_values), "H5Pset_filter(blosc)");
    }
    const hid_t type = binary16_type();
    const hid_t dataset =
        check_id(H5Dcreate2(file, "/volume", type, space, H5P_DEFAULT, properties, H5P_DEFAULT), "H5Dcreate2");
    check(H5Dwrite(dataset, type, H5S_ALL, H5S_ALL, H5P_DEFAULT, bits.data()), "H5Dwrite");
    H5Dclose(dataset);
    H5Tclose(type);
    H5Pclose(properties);
    H5Sclose(space);
    check(H5Fclose(file), "H5Fclose");
  }

  std::vector<float> read_box(const std::string& path, std::uint32_t, const ivol::Box& box) override {
    const hid_t file = check_id(H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), "H5Fopen");
    const hid_t dataset = check_id(H5Dopen2(file, "/volume", H5P_DEFAULT), "H5Dopen2");
    const hid_t space = check_id(H5Dget_space(dataset), "H5Dget_space");
    // HDF5's dimensions are [z][y][x].
    const hsize_t start[3] = {box.lo[2], box.lo[1], box.lo[0]};
    const hsize_t count[3] = {box.hi[2] - box.lo[2], box.hi[1] - box.lo[1], box.hi[0] - box.lo[0]};
    check(H5Sselect_hyperslab(space, H5S_SELECT_SET, start, nullptr, count, nullptr), "H5Sselect_hyperslab");
    const hid_t memory = check_id(H5Screate_simple(3, count, nullptr), "H5Screate_simple");
    const hid_t type = binary16_type();
    std::vector<std::uint16_t> bits(box.voxel_count());
    check(H5Dread(dataset, type, memory, space, H5P_DEFAULT, bits.data()), "H5Dread");
    H5Tclose(type);
    H5Sclose(memory);
    H5Sclose(space);
    H5Dclose(dataset);
    check(H5Fclose(file), "H5Fclose");
    std::vector<float> out(bits.size());
    for (std::size_t i = 0; i < bits.size(); ++i) out[i] = ivol::binary16_to_float(bits[i]);
    return out;
  }

 private:
  Compression compression_;
};

}  // namespace

bool hdf5_blosc_available() { return H5Zfilter_avail(kBloscFilter) > 0; }

std::string hdf5_version() {
  unsigned major = 0, minor = 0, release = 0;
  H5get_libversion(&major, &minor, &release);
  return std::to_string(major) + "." + std::to_string(minor) + "." + std::to_string(release);
}

std::vector<std::unique_ptr<PeerFormat>> hdf5_formats() {
  std::vector<std::unique_ptr<PeerFormat>> formats;
  if (hdf5_blosc_available()) {
    formats.push_back(std::make_unique<Hdf5Format>(Compression::BloscZstd));
    formats.push_back(std::make_unique<Hdf5Format>(Compression::BloscLz4));
  }
  formats.push_back(std::make_unique<Hdf5Format>(Compression::Deflate));
  return formats;
}

}  // namespace peers
