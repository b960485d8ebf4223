// libFuzzer harness for the converters' input parsers: the first byte picks
// the format (raw with a size derived from the input, TIFF, HDF5, OpenVDB),
// the rest is the file. Whatever the input, opening and reading it must
// return or throw ivol::Error: no crash, no sanitizer report.
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <string>

#include "hdf5_io.hpp"
#include "ivol/error.hpp"
#include "raw_io.hpp"
#include "slab_io.hpp"
#include "tiff_io.hpp"
#include "vdb_io.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 2) return 0;
  static const std::string path = "/dev/shm/ivol-fuzz-convert-" + std::to_string(getpid());
  FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) return 0;
  std::fwrite(data + 1, 1, size - 1, f);
  std::fclose(f);
  try {
    std::unique_ptr<ivol::convert::SlabReader> reader;
    switch (data[0] % 4) {
      case 0: {
        ivol::convert::RawLayout layout;
        layout.type = static_cast<ivol::convert::SampleType>(data[0] / 4 % 5);
        layout.dims = {static_cast<std::uint32_t>(1 + size % 7), 3, 2};
        layout.big_endian = data[0] & 0x80;
        reader = ivol::convert::open_raw_slabs(path, layout);
        break;
      }
      case 1: reader = ivol::convert::open_tiff_slabs(path); break;
      case 2: reader = ivol::convert::open_hdf5_slabs(path); break;
      case 3: (void)ivol::convert::read_vdb(path); return 0;
    }
    const ivol::convert::DenseVolume& shape = reader->shape();
    if (shape.voxel_count() * ivol::convert::sample_size(shape.type) <= (16u << 20)) {
      std::vector<std::uint8_t> buffer(shape.voxel_count() * ivol::convert::sample_size(shape.type));
      reader->read(0, shape.dims[2], buffer.data());
    }
  } catch (const ivol::Error&) {
  }
  return 0;
}
