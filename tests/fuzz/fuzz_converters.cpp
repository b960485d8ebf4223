// libFuzzer harness for the converters' input parsers: the first byte picks
// the format (volumes: raw with a size derived from the input, TIFF, HDF5,
// OpenVDB; projections: raw, TIFF, HDF5 DXchange, HDF5 NXtomo; RTK geometry
// XML; a Nikon .xtekct file and its angle files), the rest is the file.
// Whatever the input, opening and reading it must return or throw
// (ivol::Error, or std::runtime_error from the projection readers): no
// crash, no sanitizer report.
//
// libFuzzer runs it on the in-process HDF5 reader, so that a crash inside
// libhdf5 is seen (and can be told from one of ivol's); OpenVDB grids are
// skipped unless IVOL_FUZZ_VDB_IN_PROCESS=1 (fuzz_vdb.cpp is their harness).
// With IVOL_FUZZ_ISOLATED=1 (replay only) HDF5 and OpenVDB go
// through the readers users get, the library in a child process: the
// library's crashes must then be clean errors.
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "hdf5_io.hpp"
#include "isolated_worker.hpp"
#include "itk_image_io.hpp"
#include "ivol/error.hpp"
#include "ivol/recon/rtk_geometry_xml.hpp"
#include "projection_io.hpp"
#include "raw_io.hpp"
#include "slab_io.hpp"
#include "tiff_io.hpp"
#include "vdb_io.hpp"
#include "xtekct.hpp"

// The libraries' child process is this binary started again (isolated_worker.hpp).
extern "C" int LLVMFuzzerInitialize(int*, char***) {
  ivol::convert::serve_if_worker_process();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 2) return 0;
  // 0xED: the text of a Nikon .xtekct file, of a _ctdata.txt and of an .ang
  // file, and the geometry of the keys with the angles read.
  if (data[0] == 0xED) {
    const std::string text(reinterpret_cast<const char*>(data + 1), size - 1);
    try {
      (void)ivol::convert::parse_ctdata_angles(text, "fuzz", 1 + size % 5);
      (void)ivol::convert::parse_ang_angles(text, "fuzz", 1 + size % 5);
    } catch (const std::exception&) {
    }
    try {
      const ivol::convert::XtekctKeys keys = ivol::convert::parse_xtekct(text, "fuzz");
      if (keys.projections <= (1u << 16))
        (void)ivol::convert::xtekct_geometry(keys, std::vector<double>(keys.projections, 1.0), "fuzz");
    } catch (const std::exception&) {
    }
    return 0;
  }
  // First bytes 0xEA..0xEC: ITK images (MetaImage volume, NRRD volume,
  // MetaImage projections); 0xEE an HDF5 scan of either layout (NXtomo,
  // else DXchange); the others select as below (and as the kept findings
  // were made).
  const bool itk = data[0] >= 0xEA && data[0] <= 0xEC;
  static const std::string base = "/dev/shm/ivol-fuzz-convert-" + std::to_string(getpid());
  const std::string path = itk ? base + (data[0] == 0xEB ? ".nrrd" : ".mha") : base;
  FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) return 0;
  std::fwrite(data + 1, 1, size - 1, f);
  std::fclose(f);
  static const bool isolated = std::getenv("IVOL_FUZZ_ISOLATED") != nullptr;
  static const bool vdb_in_process = std::getenv("IVOL_FUZZ_VDB_IN_PROCESS") != nullptr;
  try {
    using namespace ivol::convert;
    std::unique_ptr<ProjectionReader> projections;
    if (itk && data[0] == 0xEC) {
      IntensityOptions intensity;
      intensity.incident_intensity = 1000.0;
      projections = open_itk_image_projections(path, StoredQuantity::LineIntegrals, intensity).projections;
    }
    const bool hdf5_scan = data[0] == 0xEE;
    if (hdf5_scan)
      projections =
          (isolated ? open_hdf5_projections(path, {true, 1e-3}) : open_hdf5_projections_in_process(path, {true, 1e-3}))
              .projections;
    switch (itk || hdf5_scan ? -1 : data[0] % 8) {
      case 4: {
        RawProjectionLayout layout;
        layout.columns = 1 + static_cast<int>(size % 5);
        layout.rows = 2;
        layout.views = 1 + size % 3;
        layout.sample = data[0] & 0x80 ? RawSampleType::UInt16 : RawSampleType::Float32;
        layout.quantity = data[0] & 0x40 ? StoredQuantity::Intensities : StoredQuantity::LineIntegrals;
        IntensityOptions intensity;
        intensity.incident_intensity = 1000.0;
        projections = open_raw_projections(path, layout, intensity);
        break;
      }
      case 5:
        projections = open_tiff_projections(path, StoredQuantity::LineIntegrals);
        break;
      case 6:
        projections = (isolated ? open_dxchange_projections(path, {true, 1e-3})
                                : open_dxchange_projections_in_process(path, {true, 1e-3}))
                          .projections;
        break;
      case 7:
        (void)ivol::recon::read_rtk_geometry_xml(path, {8, 8, 1.0, 1.0}, -3.5, -3.5);
        return 0;
      default:
        break;
    }
    if (projections) {
      const std::size_t image = static_cast<std::size_t>(projections->columns()) * projections->rows();
      if (image * projections->view_count() <= (4u << 20)) {
        std::vector<float> rows(image);
        for (std::size_t v = 0; v < projections->view_count(); ++v)
          projections->read_rows(v, 0, projections->rows(), rows.data());
      }
      return 0;
    }
    std::unique_ptr<ivol::convert::SlabReader> reader;
    if (itk) reader = open_itk_image_slabs(path);
    switch (itk ? -1 : data[0] % 4) {
      case 0: {
        ivol::convert::RawLayout layout;
        layout.type = static_cast<ivol::convert::SampleType>(data[0] / 4 % 5);
        layout.dims = {static_cast<std::uint32_t>(1 + size % 7), 3, 2};
        layout.big_endian = data[0] & 0x80;
        reader = ivol::convert::open_raw_slabs(path, layout);
        break;
      }
      case 1:
        reader = ivol::convert::open_tiff_slabs(path);
        break;
      case 2:
        reader = isolated ? open_hdf5_slabs(path) : open_hdf5_slabs_in_process(path);
        break;
      case 3:
        // libopenvdb in process allocates what a block header claims and
        // crashes on damaged grids (regressions/libopenvdb): such findings
        // drowned every other one here (167 of 167 in the last run). Its
        // own harness (fuzz_vdb.cpp) fuzzes it; here it is read only
        // through the child users get, when replaying, or in process on
        // request (IVOL_FUZZ_VDB_IN_PROCESS=1).
        if (isolated) {
          reader = open_vdb_slabs(path, "", nullptr, std::uint64_t{256} << 20);
        } else if (vdb_in_process) {
          // A budget well inside libFuzzer's 2 GB RSS limit: a grid whose
          // dense box exceeds it must be refused, not allocated.
          reader = open_vdb_slabs_in_process(path, "", nullptr, std::uint64_t{256} << 20);
        } else {
          return 0;
        }
        break;
    }
    const ivol::convert::DenseVolume& shape = reader->shape();
    if (shape.voxel_count() * ivol::convert::sample_size(shape.type) <= (16u << 20)) {
      std::vector<std::uint8_t> buffer(shape.voxel_count() * ivol::convert::sample_size(shape.type));
      reader->read(0, shape.dims[2], buffer.data());
    }
  } catch (const std::exception&) {
  }
  return 0;
}
